"""Speed of the sensory coder (paper §3.3): encode + dictionary update of both scales.

``run()`` times, side by side in one process, the Gram-form matching pursuit with its steps in
the compiled kernel (``gram_cpp``, what the coder uses when the kernel builds) and in the
numpy/torch loop (``gram_torch``, the fallback), and the straightforward pursuit that recomputes
all correlations at every step (``recompute``), for one frame pair and for a batch of 16, with
learning on (the training path) and off (frozen dictionaries, cached Gram matrix). The keys
ending ``_gram_ms`` repeat the figure of the Gram form the coder uses by default. Each
repetition times every variant in turn, so machine noise hits them alike; medians are reported
in milliseconds. Run as ``python -m parallax.tools.bench.coding [repeats]``.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable

import cv2
import numpy as np
import torch

from parallax.coding import native
from parallax.coding.coder import MultiScaleCoder
from parallax.tools.bench.timing import interleaved_medians_ms

SCALE_SPECS = {
    "coarse": {"window": 250, "subsample": 8, "patch": 10, "stride": 1},
    "fine": {"window": 150, "subsample": 2, "patch": 10, "stride": 4},
}
IMAGE_SIZE = 256
WARM_UP = 5


def _frames(batch: int, shift: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """A photograph (skimage's astronaut) as uint8 RGB I0, and I(t) moved right by ``shift`` px."""
    import skimage.data

    photo = cv2.resize(skimage.data.astronaut(), (IMAGE_SIZE + 16 * batch, IMAGE_SIZE + 16 * batch))
    references = np.stack(
        [
            photo[8 * i : 8 * i + IMAGE_SIZE, 8 * i + 16 : 8 * i + 16 + IMAGE_SIZE]
            for i in range(batch)
        ]
    )
    currents = np.stack(
        [
            photo[8 * i : 8 * i + IMAGE_SIZE, 8 * i + 16 - shift : 8 * i + 16 - shift + IMAGE_SIZE]
            for i in range(batch)
        ]
    )
    return references, currents


def _coder(pursuit: str, learn: bool, scales: list[str]) -> MultiScaleCoder:
    return MultiScaleCoder(
        scales,
        SCALE_SPECS,
        atoms=288,
        sparsity=10,
        learning_rate=0.2,
        normalisation="per_half",
        learn=learn,
        seed=0,
        image_size=IMAGE_SIZE,
        pursuit=pursuit,
    )


def _gram_variants() -> tuple[str, ...]:
    """The Gram-form variants to time: the compiled kernel only where it builds."""
    return ("gram_cpp", "gram_torch") if native.load_kernels() is not None else ("gram_torch",)


def _operations() -> dict[str, Callable[[], object]]:
    operations: dict[str, Callable[[], object]] = {}
    grams = _gram_variants()
    for batch in (1, 16):
        references, currents = _frames(batch)
        for pursuit in (*grams, "recompute"):
            for learn in (True, False):
                coder = _coder(pursuit, learn, ["coarse", "fine"])
                coder.set_reference(references)
                mode = "encode_update" if learn else "encode_frozen"
                operations[f"{mode}_both_B{batch}_{pursuit}_ms"] = (
                    lambda coder=coder, currents=currents: coder(currents)
                )
        for scale in ("coarse", "fine"):
            for pursuit in grams:
                coder = _coder(pursuit, True, [scale])
                coder.set_reference(references)
                operations[f"encode_update_{scale}_B{batch}_{pursuit}_ms"] = (
                    lambda coder=coder, currents=currents: coder(currents)
                )
        reference_coder = _coder("gram", True, ["coarse", "fine"])
        operations[f"set_reference_both_B{batch}_ms"] = (
            lambda coder=reference_coder, references=references: coder.set_reference(references)
        )
    return operations


def run(repeats: int = 50) -> dict[str, float]:
    """Median milliseconds per operation (names say scales, batch B, pursuit, learning), the
    speed-ups of the Gram form over the recomputing pursuit (``_speedup``) and of the compiled
    kernel over the numpy/torch loop (``_cpp_speedup``), and the torch thread count; once with
    the process's default thread count and once with a single thread (keys ending ``_1thread``)."""
    results: dict[str, float] = {}
    default_threads = torch.get_num_threads()
    grams = _gram_variants()
    default = grams[0]  # what pursuit="gram" runs: the kernel when it builds
    for threads, suffix in ((default_threads, ""), (1, "_1thread")):
        torch.set_num_threads(threads)
        try:
            timings = interleaved_medians_ms(_operations(), repeats, warmup=WARM_UP)
        finally:
            torch.set_num_threads(default_threads)
        for batch in (1, 16):
            for mode in ("encode_update", "encode_frozen"):
                gram = timings[f"{mode}_both_B{batch}_gram_ms"] = timings[
                    f"{mode}_both_B{batch}_{default}_ms"
                ]
                recompute = timings[f"{mode}_both_B{batch}_recompute_ms"]
                timings[f"{mode}_both_B{batch}_speedup"] = recompute / gram
                if "gram_cpp" in grams:
                    timings[f"{mode}_both_B{batch}_cpp_speedup"] = (
                        timings[f"{mode}_both_B{batch}_gram_torch_ms"]
                        / timings[f"{mode}_both_B{batch}_gram_cpp_ms"]
                    )
            for scale in ("coarse", "fine"):
                timings[f"encode_update_{scale}_B{batch}_gram_ms"] = timings[
                    f"encode_update_{scale}_B{batch}_{default}_ms"
                ]
        results.update({name + suffix: value for name, value in sorted(timings.items())})
        results[f"torch_threads{suffix}"] = float(threads)
    results["repeats"] = float(repeats)
    return results


if __name__ == "__main__":
    print(json.dumps(run(int(sys.argv[1]) if len(sys.argv) > 1 else 50), indent=2))
