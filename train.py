"""`python train.py ...`: the training command, the same as `roll-train ...`
(roll_jax/train_cli.py; `python train.py --help` lists its flags)."""

import sys

from roll_jax.train_cli import main

if __name__ == "__main__":
    sys.exit(main())
