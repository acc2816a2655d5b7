"""The paper's Figure 4 from cells trained anywhere (separate grids, `train.py` runs, or the
metrics.csv files kept in bench/results/):

    roll-analysis figure4 --cell TASK ALGO PATH [--cell ...] --png FILE [--out FILE.json]
        [--from-steps N]

PATH is a run directory (its metrics.csv; its config.json must name TASK and ALGO's algorithm)
or a metrics.csv file. One panel per task, in the order of configs.train.TASKS, with each
cell's median over seeds and 25-75% band (`reproduce.figure4`). Per cell the JSON holds
`reproduce.final_stats` (median / 25% / 75% over seeds at the last evaluation, and the area
under the curve); per task, every other cell is paired with its ROLL cell (`compare.compare`:
each evaluation's seeds are pairs, as the cells of one base seed share their test goals) up to
the last evaluation both have, so an unfinished cell is compared on what it has, and the JSON
says how far that is. `roll-reproduce` draws the same figure for the cells of one grid.
"""

from __future__ import annotations

import argparse
import json
import os

from roll_jax.analysis.compare import compare, write_json
from roll_jax.analysis.stats import format_distance
from roll_jax.training import reproduce, run_dir

REFERENCE = "roll"


def read_cell(task: str, variant: str, path: str) -> tuple[list[dict], int | None]:
    """(metrics rows, the base seed when PATH is a run directory) of one cell; ValueError naming
    the path when it is not a run of `task` / `variant`'s algorithm, or holds no evaluation."""
    seed = None
    if os.path.isdir(path):
        cfg = run_dir.read_config(path)
        algo = reproduce.VARIANTS[variant][0]
        if (cfg.task, cfg.algo) != (task, algo):
            raise ValueError(f"{path} is a {cfg.task} / {cfg.algo} run, not {task} / {algo}")
        inputs = os.path.join(path, run_dir.INPUTS)
        if os.path.exists(inputs):
            with open(inputs) as f:
                seed = json.load(f).get("seed")
        path = os.path.join(path, "metrics.csv")
    if not os.path.exists(path):
        raise ValueError(f"{path}: no such run directory or metrics.csv")
    rows = run_dir.read_rows(path, 2**62)
    if not rows:
        raise ValueError(f"{path} holds no evaluation")
    return rows, seed


def summarise(cells: dict[tuple[str, str], list[dict]], from_steps: int = 0) -> dict:
    """Per task: each cell's final_stats, and each non-ROLL cell paired with the task's ROLL
    cell over their common evaluations from `from_steps` on."""
    out: dict[str, dict] = {}
    for (task, variant), rows in cells.items():
        entry = out.setdefault(task, {"cells": {}, "paired_with_roll": {}})
        entry["cells"][variant] = reproduce.final_stats(rows)
    for task, entry in out.items():
        ref = cells.get((task, REFERENCE))
        for variant in entry["cells"]:
            if variant == REFERENCE or ref is None:
                continue
            rows = cells[(task, variant)]
            to = min(max(r["env_steps"] for r in ref), max(r["env_steps"] for r in rows))
            entry["paired_with_roll"][variant] = compare(ref, rows, from_steps, to)
    return out


def main(argv=None) -> int:
    from configs.train import TASKS

    p = argparse.ArgumentParser(prog="roll-analysis figure4", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cell", nargs=3, action="append", required=True,
                   metavar=("TASK", "ALGO", "PATH"),
                   help=f"one cell: a task ({', '.join(TASKS)}), a grid variant "
                        f"({', '.join(reproduce.VARIANTS)}) and its run directory or "
                        "metrics.csv; repeat per cell")
    p.add_argument("--png", required=True, metavar="FILE", help="the figure")
    p.add_argument("--out", default=None, metavar="FILE",
                   help="the per-cell and paired figures as JSON")
    p.add_argument("--from-steps", type=int, default=0,
                   help="pair the evaluations from this env step on (default 0)")
    a = p.parse_args(argv)
    cells, seeds = {}, {}
    for task, variant, path in a.cell:
        if task not in TASKS:
            p.error(f"--cell: unknown task {task!r}; expected one of {', '.join(TASKS)}")
        if variant not in reproduce.VARIANTS:
            p.error(f"--cell: unknown algorithm {variant!r}; expected one of "
                    f"{', '.join(reproduce.VARIANTS)}")
        if (task, variant) in cells:
            p.error(f"--cell {task} {variant} is given twice")
        try:
            cells[(task, variant)], seeds[(task, variant)] = read_cell(task, variant, path)
        except (FileNotFoundError, ValueError) as e:
            p.error(str(e))
    for task in TASKS:
        known = {v: s for (t, v), s in seeds.items() if t == task and s is not None}
        if len(set(known.values())) > 1:
            p.error(f"{task}: the cells have different base seeds {known}: their test goals "
                    "differ, so they cannot be paired")
    try:
        summary = summarise(cells, a.from_steps)
    except ValueError as e:
        p.error(str(e))
    curves = {t: {v: rows for (tt, v), rows in cells.items() if tt == t}
              for t in TASKS if any(tt == t for tt, _ in cells)}
    os.makedirs(os.path.dirname(os.path.abspath(a.png)), exist_ok=True)
    reproduce.figure4(curves, a.png)
    print(f"wrote {a.png}")
    for task, entry in summary.items():
        def fmt(x, sign="", task=task):
            return format_distance(task, x, sign)

        for variant, s in entry["cells"].items():
            print(f"{task:14s} {variant:22s} {s['env_steps']:6d} steps: median "
                  f"{fmt(s['median'])} ({fmt(s['q25'])} - {fmt(s['q75'])})")
        for variant, pair in entry["paired_with_roll"].items():
            print(f"{task:14s} ROLL - {variant}: {fmt(pair['paired_diff_mean'], '+')} +- "
                  f"{fmt(pair['paired_diff_sem'])} paired to {pair['to_steps']}, "
                  f"ROLL below in {pair['evaluations_a_below_b']}/{pair['n_evaluations']}")
    if a.out:
        write_json(a.out, {"cells": {f"{t} {v}": path for t, v, path in a.cell},
                           "from_steps": a.from_steps, "tasks": summary})
    return 0
