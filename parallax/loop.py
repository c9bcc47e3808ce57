"""The paper's loop (§3.2, Fig. 3): one stimulus presentation, as one plain function.

For each lateral position l_p, for each iteration, each turn of robots: the executor encodes I(t)
against I0 (state θ, reward −(eC+eF)); the tally notes q_p, α* and the coder's numbers; the
pursuer learns from the step into I(t) and acts; the worlds step, and the dictionaries learn from
every turn's encoding. The pan at a trial's last iteration is q_p (with the body sweeping L in one
trial, env.motion=continuous: the pan as it passes l_p).

Each box is one object: the executor (:class:`parallax.executor.InOrder`, every step on this
thread, or :class:`parallax.lockstep.Lockstep`, the same steps scheduled on threads) runs what
touches the worlds and the dictionaries; the pursuer (:class:`parallax.policy.Pursuer`) is the
policy's bookkeeping; the tally (:class:`parallax.presentation.Tally`) gathers the record; the
route (:mod:`parallax.routes`) says where to go, before the first trial and at the end of each.
"""

from __future__ import annotations

from parallax.executor import Executor
from parallax.parts import Parts
from parallax.policy import Pursuer
from parallax.presentation import Presentation, Tally
from parallax.routes import SWEEP, Route


def presentation(
    parts: Parts,
    run: Executor,
    *,
    learn: bool = True,
    greedy: bool = False,
    route: Route = SWEEP,
    keep_view: bool = False,
) -> Presentation:
    """All robots live through one presentation on ``route``; frozen (``learn`` false), neither
    the policy nor the dictionaries learn, and acting does not move the policy's running feature
    statistics; ``greedy``: the policy's mode instead of a draw from it."""
    task = parts.worlds[0].task
    lateral, trial_length = list(task.lateral_positions), task.trial_length
    tally = Tally(len(parts.worlds), lateral, trial_length, route.chosen, task.continuous)
    with run, Pursuer(parts.policy, run.turns, learn=learn, greedy=greedy) as pursuer:
        p = route.where_next(run, [], tally.so_far())  # a chosen route starts the worlds there
        run.reset(learn)  # each world: its stimulus, I0 at l0
        while p is not None:  # for each lateral position l_p
            tally.visit(p)
            for t in range(trial_length):  # for each iteration
                for turn in range(len(run.turns)):  # each turn of robots
                    frames = run.frames(turn)  # encode I(t)
                    tally.seen(frames)  # q_p and α*, the coder's reward and errors
                    pursuer.see(frames)  # the policy learns from the step into I(t)
                    if t == trial_length - 1 and turn == 0:  # where next, from q_p
                        after = route.where_next(run, tally.visited, tally.so_far())
                    if t < trial_length - 1 or after is not None:
                        run.step(turn, pursuer.act(turn))  # act; the worlds step
            p = after
    return tally.presentation(keep_view, pursuer.statistics())
