"""`python -m parallax.tools.analysis.landscape RUN`: the reward of eq. (6) around the target pan
α*, and the policy's mean pan step there, for a trained run (paper §3.3–3.4).

The pursuit can only be as good as the reward it climbs: the eye settles where −(eC + eF) peaks.
For a few (texture, distance) pairs at one lateral position this sweeps the pan from α* − span to
α* + span with the run's frozen dictionaries and policy, and prints per offset the mean reward,
the mean error of each scale and the policy's expected pan step E_π[a]; then the offset where
each stimulus's reward peaks. A peak away from 0 means the learnt dictionaries favour a
disparity other than zero (docs/improvements.md §1: a fast-adapting dictionary peaks short of
α*).
With ``policy.reward_change_gain`` > 0 the policy's reward-change entry is that of an eye arriving
at each offset from the previous one by a step towards +, the way a trial sweeps from pan 0
towards α* and, if it runs away, beyond. Nothing is learnt; the run directory is only read.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch

from parallax import checkpoint
from parallax.config import load_run_config
from parallax.experiment import Experiment
from parallax.tools.analysis.best_match import views_around_target
from parallax.tools.console import footer, header, progress


def sweep(
    run_dir: str | Path,
    checkpoint_name: str = checkpoint.CHECKPOINT_NAME,
    lateral_position: float | None = None,
    distances=(3.0, 5.0, 7.0, 10.0),
    textures: int = 4,
    span: float = 1.0,
    step: float = 0.05,
    texture_indices=None,
    bar=None,
) -> dict:
    """Rewards (stimuli × offsets), per-scale errors and E_π[a] around α*; see the module doc.
    ``bar``: a progress bar moved on by each stimulus."""
    run_dir = Path(run_dir)
    cfg = load_run_config(run_dir)
    exp = Experiment(cfg)
    try:
        exp.load_state_dict(checkpoint.load(run_dir / checkpoint_name)["experiment"])
        exp.coder.eval()
        exp.policy.eval()
        lateral = exp.lateral_positions[0] if lateral_position is None else float(lateral_position)
        offsets = np.round(np.arange(-span, span + step / 2, step), 6)
        actions = exp.policy.action_values.cpu().numpy()
        rewards, errors, mean_steps = [], [], []
        for distance in distances:
            for texture in range(textures) if texture_indices is None else texture_indices:
                reference, target, views = views_around_target(
                    exp.envs[0], texture, float(distance), lateral, offsets
                )
                reference_image = torch.from_numpy(reference[None].copy())
                exp.coder.set_reference(reference_image)
                baseline = (
                    exp.coder(reference_image, learn=False).state
                    if exp.policy.uses_reference_state
                    else None
                )
                row_r, row_e, row_a = [], [], []
                for offset, frame in zip(offsets, views):
                    out = exp.coder(torch.from_numpy(frame[None].copy()), learn=False)
                    reward_here = out.reward.cpu().numpy().astype(np.float64)
                    # with policy.reward_change_gain: as if the eye had come from the previous
                    # offset by a leftward turn (+), as it does from pan 0 towards α* and beyond
                    change = (reward_here, np.array([row_r[-1]]), np.ones(1)) if row_r else None
                    state = exp.policy.state(
                        out.state, baseline, np.array([target + offset]), lateral, change
                    )
                    row_r.append(float(out.reward[0]))
                    row_e.append([float(e[0]) for e in out.errors.values()])
                    row_a.append(float(exp.policy.probabilities(state)[0].cpu().numpy() @ actions))
                rewards.append(row_r)
                errors.append(row_e)
                if bar is not None:
                    bar.update()
                mean_steps.append(row_a)
        scales = list(exp.coder.dictionaries)
    finally:
        exp.close()
    rewards_arr = np.asarray(rewards)
    return {
        "run_dir": str(run_dir),
        "checkpoint": checkpoint_name,
        "lateral_position_m": lateral,
        "offsets_deg": offsets.tolist(),
        "scales": scales,
        "reward": rewards_arr.mean(axis=0).tolist(),
        "errors": {
            s: np.asarray(errors)[:, :, i].mean(axis=0).tolist() for i, s in enumerate(scales)
        },
        "mean_step_deg": np.asarray(mean_steps).mean(axis=0).tolist(),
        "peak_offsets_deg": offsets[rewards_arr.argmax(axis=1)].tolist(),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m parallax.tools.analysis.landscape", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("run_dirs", nargs="+", metavar="RUN", help="one or more run directories")
    parser.add_argument("--checkpoint", default=checkpoint.CHECKPOINT_NAME)
    parser.add_argument(
        "--lateral",
        type=float,
        default=None,
        help="lateral position in metres (default: the run's first)",
    )
    parser.add_argument("--distances", type=float, nargs="+", default=[3.0, 5.0, 7.0, 10.0])
    parser.add_argument("--textures", type=int, default=4, help="training textures per distance")
    parser.add_argument(
        "--texture-indices",
        type=int,
        nargs="+",
        default=None,
        help="these training textures instead of the first --textures",
    )
    parser.add_argument("--span", type=float, default=1.0, help="largest |pan − α*|, degrees")
    parser.add_argument("--json", help="also write the result here (a list when several runs)")
    parser.add_argument("--plot", help="also plot E_π[a] and the reward of every run into this PNG")
    args = parser.parse_args(argv)
    for run_dir in args.run_dirs:
        if not (Path(run_dir) / args.checkpoint).is_file():
            print(f"[landscape] {run_dir} has no {args.checkpoint}", file=sys.stderr)
            return 2
    if args.textures < 1 or args.span <= 0:
        print(
            "[landscape] --textures must be ≥ 1 and --span > 0, "
            f"got {args.textures} and {args.span}",
            file=sys.stderr,
        )
        return 2
    torch.set_num_threads(1)
    stimuli = len(args.distances) * len(args.texture_indices or range(args.textures))
    header(
        "landscape",
        f"the reward and E_π[a] within ±{args.span:g}° of α* for {len(args.run_dirs)} run"
        + "s" * (len(args.run_dirs) != 1),
        checkpoint=args.checkpoint,
        stimuli=f"{stimuli} per run ({len(args.distances)} distances)",
        output=", ".join(str(Path(p).resolve()) for p in (args.json, args.plot) if p)
        or "the tables, printed",
    )
    bar = progress(total=stimuli * len(args.run_dirs), desc="stimuli", unit="stimulus")
    results = []
    for run_dir in args.run_dirs:
        result = sweep(
            run_dir,
            args.checkpoint,
            args.lateral,
            args.distances,
            args.textures,
            args.span,
            texture_indices=args.texture_indices,
            bar=bar,
        )
        results.append(result)
        if len(args.run_dirs) > 1:
            print(f"== {run_dir}")
        _print_table(result)
    bar.close()
    if args.json:
        payload = results[0] if len(results) == 1 else results
        Path(args.json).write_text(json.dumps(payload, indent=1))
        footer("landscape", [args.json])
    if args.plot:
        from parallax.tools.plots import pursuit_landscape

        # a run given twice gets its position in the list, so no line hides another
        labels = [
            f"{_label(run)} [{i + 1}]" if args.run_dirs.count(run) > 1 else _label(run)
            for i, run in enumerate(args.run_dirs)
        ]
        print(f"[landscape] plot: {pursuit_landscape(dict(zip(labels, results)), args.plot)}")
    return 0


def _print_table(result: dict) -> None:
    header = (
        "offset °   reward  " + "  ".join(f"e_{s:<6}" for s in result["scales"]) + "  E[step] °"
    )
    print(header)
    for i, offset in enumerate(result["offsets_deg"]):
        errs = "  ".join(f"{result['errors'][s][i]:.4f}  " for s in result["scales"])
        print(
            f"{offset:+7.2f}  {result['reward'][i]:8.4f}  {errs}  {result['mean_step_deg'][i]:+.3f}"
        )
    peaks = np.asarray(result["peak_offsets_deg"])
    print(
        f"reward peak − α* per stimulus: median {np.median(peaks):+.2f}°, "
        f"range {peaks.min():+.2f}…{peaks.max():+.2f}° ({len(peaks)} stimuli)"
    )


def _label(run_dir: str) -> str:
    """A short legend entry: the run's experiment, seed and beyond-the-paper policy settings."""
    cfg = load_run_config(Path(run_dir))
    policy = cfg.policy
    eye = float(policy.get("eye_position_reference_m", 0.0) or 0.0)
    extras = [f"feature_norm={policy.feature_norm}"] + (
        [f"eye_position_reference_m={eye:g}"] if eye else []
    )
    return f"{cfg.curriculum.name} seed {cfg.seed}: " + ", ".join(extras)


if __name__ == "__main__":
    sys.exit(main())
