"""python -m bench NAME [ARGS]: run benchmark NAME (`python -m bench NAME --help`: its
arguments); each writes bench/results/NAME.json in the suite's one schema (bench/common.py).
`make bench NAME=envs ARGS="--n 1 64"` is the same."""

from __future__ import annotations

import importlib
import sys

BENCHMARKS = {
    "envs": "MJX env steps/s with and without rendering, compile times, parity with C MuJoCo",
    "render_vs_mujoco": "the JAX ray caster against MuJoCo's OpenGL renderer: labels, speed",
    "segmentation": "MOG2 against cv2 (speed, parity), U-Net and segment throughput",
    "encoders": "VAE and LSTM train steps/s at the paper's batches, encoding throughput",
    "roofline": "encoders', U-Net's and SAC's time against hand-counted FLOPs and matmul",
    "sac": "where a SAC update's time goes: the update, HER sampling, both in the loop",
    "chunk": "the compiled training chunk's env steps/s and its parts",
    "learning": "a training run of the real loop and its learning curve",
    "grid": "the smoke reproduction grid's wall time and where it goes",
    "brax_sac": "Brax's own SAC trainer on puck_push from state observations: curve, wall time",
    "gpu_check": "what a lent GPU runs: rendered env steps/s at 1024 and 4096 envs, a "
                 "paper-preset chunk and its compile",
}


def usage() -> str:
    return __doc__ + "\n\nbenchmarks:\n" + "\n".join(
        f"  {name:17s} {text}" for name, text in BENCHMARKS.items())


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(usage())
        return 0
    if argv[0] not in BENCHMARKS:
        print(f"unknown benchmark {argv[0]!r}\n\n{usage()}", file=sys.stderr)
        return 2
    importlib.import_module(f"bench.{argv[0]}").main(argv[1:])
    return 0


if __name__ == "__main__":
    sys.exit(main())
