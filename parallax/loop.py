"""The paper's loop (§3.2, Fig. 3) as one plain function, on one thread.

For each lateral position of the presentation, for each iteration: each turn of robots is
encoded (state θ, reward −(eC+eF)), the policy learns from the step into it and acts, and the
turn's worlds step; then the dictionary step from every turn's encoding. The pan at a trial's
last iteration is q_p. :func:`presentation` is the reference that
:meth:`parallax.experiment.Experiment.run_presentation` (the lockstep, which schedules the same
steps on threads) is tested against, bit for bit. A planned route (§7) is the strategy the loop
asks "where next?" at the end of each trial; without one the robots sweep L in order.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from parallax.experiment import Experiment, Presentation, _Step, _Tally
from parallax.lockstep import robot_turns, stack_images

#: Where next: (positions visited so far, the presentation as it stands) → an index into L, or
#: None to stop there.
Route = Callable[[list[int], Presentation], int | None]


def presentation(
    exp: Experiment, learn: bool = True, greedy: bool = False, route: Route | None = None
) -> Presentation:
    """All robots live through one presentation, every step on this thread in the paper's order;
    frozen (``learn`` false), acting does not move the policy's running feature statistics."""
    was_training = exp.policy.training
    exp.policy.train(learn and was_training)
    try:
        return _presentation(exp, learn, greedy, route)
    finally:
        exp.policy.train(was_training)


def _presentation(exp: Experiment, learn: bool, greedy: bool, route: Route | None) -> Presentation:
    coder, policy, envs, device = exp.coder, exp.policy, exp.envs, exp.device
    lateral, last_t = list(envs[0].task.lateral_positions), exp.trial_length - 1
    tally = _Tally(exp.robots, lateral, exp.trial_length, routed=route is not None)
    where_next = route or (lambda visited, _: len(visited) if len(visited) < len(lateral) else None)
    p = where_next([], tally.presentation(None, False))  # the first lateral position
    if route is not None:
        envs[0].task.start_route(lateral[p])
    turns = robot_turns(exp.robots, exp.robots_per_turn)
    timesteps = [env.reset() for env in envs]  # each world: its stimulus, I0 at l0
    obs = [ts.observation for ts in timesteps]
    coder.set_reference(stack_images(obs, "reference", device))
    previous: list[_Step | None] = [None] * len(turns)  # each turn's last step, to learn from
    reference: list[torch.Tensor | None] = [None] * len(turns)  # θ(I0, I0) of each turn
    visited: list[int] = []
    while p is not None:  # for each lateral position l_p
        visited.append(p)
        for t in range(exp.trial_length):  # for each iteration
            encodings = []
            for k, robots in enumerate(turns):
                turn = obs[robots]
                if t == 0:  # a new trial: the step into it crossed a reset, not learnt
                    previous[k] = None
                    if policy.uses_reference_state:
                        images = stack_images(turn, "reference", device)
                        reference[k] = coder.encode(images, robots).output.state
                encodings.append(coder.encode(stack_images(turn, "image", device), robots))
                out, pans = encodings[-1].output, np.array([float(o["pan"]) for o in turn])
                rewards = out.reward.cpu().numpy().astype(np.float64)
                tally.encoded(turn, out, pans, rewards, p, robots)
                before = previous[k]  # learn from the step into this image
                change = None if before is None else (rewards, before.rewards, before.increments)
                state = policy.state(out.state, reference[k], pans, lateral[p], change)
                if learn and before is not None:
                    valid = torch.ones(len(turn), dtype=torch.bool, device=device)
                    transition = (before.state, before.action, out.reward, state, valid)
                    tally.updated(policy.update(*transition))
                if t == last_t:  # where next, from the trial just ended (q_p)
                    if k == 0:
                        if route is not None:
                            tally.visited.append(p)
                        after = where_next(list(visited), tally.presentation(obs, False))
                    if after is None:
                        continue
                    if after in visited:
                        raise ValueError(f"the route visits position {after} of L twice")
                    if route is not None:
                        envs[0].task.visit_next(lateral[after])
                action = policy.act(state, greedy=greedy)  # act
                increments = policy.action_values[action].cpu().numpy()
                previous[k] = _Step(state, action, rewards, increments)
                for b, increment in zip(range(robots.start, robots.stop), increments, strict=True):
                    obs[b] = envs[b].step(float(increment)).observation  # the world steps
            if learn and coder.learn:
                coder.learn_from(encodings)  # the dictionary step
        p = after
    return tally.presentation(obs, False)
