"""`python train.py ...`: the training command, the same as `roll-train ...`
(roll_jax/training/cli.py; `python train.py --help` lists its flags)."""

import sys

from roll_jax.training.cli import main

if __name__ == "__main__":
    sys.exit(main())
