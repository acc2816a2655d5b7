"""The paper's experiment grid: tasks x algorithms (x seeds, in one run each), ablations,
Figure 4, the ablation figure and a results table.

    roll-reproduce --preset paper --out runs/paper
    roll-reproduce --preset smoke --out runs/smoke --tasks puck_push --seeds 2
    roll-reproduce ... --ablations            # + ROLL ablations on hurdle_top
    roll-reproduce ... --report-only          # redraw from the runs on disk
    roll-reproduce ... --jobs 2               # 2 cells at once (CPU)
    roll-reproduce ... --algos roll skewfit oracle   # + the state oracle's cells

Each cell is one `roll_jax.training.driver.run` in DIR/runs/TASK__VARIANT (all its seeds in one
program: vmapped on a GPU, one after the other on a CPU, `--seed-batch`; sharded over
--devices). A run with the completion marker is skipped (never rerun, never overwritten); an
incomplete one is resumed from its last checkpoint. Every cell's config is
built, and checked against what DIR already holds, before anything runs. The segmentation is
fitted once per task (DIR/segmentation/TASK, shared by the task's ROLL runs: same seed, same
config, so the same fit); pre-training datasets and models are shared the same way
(DIR/pretrain, keyed by what they were built from). Then DIR/figure4.png, DIR/ablations.png
(with --ablations), DIR/results.md and DIR/results.csv are drawn from the runs' metrics.csv
files. (`python -m roll_jax.training.reproduce` is the same command without installing the
package; --preset defaults to cpu.)
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import os
import sys
import time

import numpy as np

from configs.overrides import parse_overrides
from configs.train import ALGOS, PRESETS, TASKS, build_config
from roll_jax.training import plots
from roll_jax.training.run_dir import check_resume, is_complete, read_rows

# (roll_jax.training.driver, and with it JAX, is imported where a cell runs: --help and --dry-run do
# without it.)

ABLATION_TASK = "hurdle_top"
# variant -> (algo, ablation flags for build_config)
VARIANTS = {
    "roll": ("roll", {}),
    "skewfit": ("skewfit", {}),
    "roll_no_matching_loss": ("roll", {"matching_loss": False}),
    "roll_no_lstm": ("roll", {"use_lstm": False}),
    "roll_no_object_vae": ("roll", {"use_object_vae": False}),
    "oracle": ("oracle", {}),
}
ABLATIONS = ("roll", "roll_no_matching_loss", "roll_no_lstm", "roll_no_object_vae")
LABELS = {"roll": "ROLL", "skewfit": "Skew-Fit", "roll_no_matching_loss": "ROLL, no matching loss",
          "roll_no_lstm": "ROLL, no LSTM", "roll_no_object_vae": "ROLL, no object-VAE",
          "oracle": "state oracle"}
# one colour per variant in every panel
COLORS = {"roll": "C0", "skewfit": "C1", "oracle": "C2", "roll_no_matching_loss": "C3",
          "roll_no_lstm": "C4", "roll_no_object_vae": "C5"}
# Fields the grid sets itself; a --set of them would contradict it.
GRID_FIELDS = ("task", "algo", "preset", "seeds", "matching_loss", "use_lstm", "use_object_vae")
METRIC = "final_distance"
DEFAULT_SEEDS = {"paper": 6, "smoke": 2}
DEFAULT_PRESET = "cpu"
DEFAULT_ALGOS = ("roll", "skewfit")


@dataclasses.dataclass(frozen=True)
class Cell:
    task: str
    variant: str
    cfg: object  # TrainConfig
    out: str


def run_dir(out: str, task: str, variant: str) -> str:
    return os.path.join(out, "runs", f"{task}__{variant}")


def parse_args(argv=None):
    p = argparse.ArgumentParser(prog="roll-reproduce", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--preset", default=DEFAULT_PRESET, metavar="PRESET",
                   help=f"one of {', '.join(PRESETS)} (configs/presets.py; default "
                        f"{DEFAULT_PRESET})")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="grid directory: DIR/runs/TASK__VARIANT, figures and tables")
    p.add_argument("--tasks", nargs="+", default=list(TASKS), metavar="TASK",
                   help=f"some of {', '.join(TASKS)} (default: all)")
    p.add_argument("--algos", nargs="+", default=list(DEFAULT_ALGOS), metavar="ALGO",
                   help=f"some of {', '.join(ALGOS)} (default: {' '.join(DEFAULT_ALGOS)}; "
                        "oracle: the state oracle through the same loop)")
    p.add_argument("--ablations", action="store_true",
                   help=f"also ROLL without matching loss / LSTM / object-VAE on {ABLATION_TASK}")
    p.add_argument("--seeds", type=int, default=None,
                   help="seeds per run; default 2 with --preset smoke (a median and a band, "
                        "at CPU cost), otherwise 6 (the paper's)")
    p.add_argument("--seed", type=int, default=0, help="base PRNG seed of every run (default 0)")
    p.add_argument("--devices", default="all",
                   help="'all' or N: shard the seeds over devices (default all)")
    p.add_argument("--seed-batch", default="auto",
                   help="'auto' or N: seeds vmapped side by side per device (as train.py)")
    p.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                   help="config overrides for every run (as train.py --set)")
    p.add_argument("--jobs", type=int, default=1,
                   help="cells trained side by side in worker processes (CPU: XLA compiles on "
                        "one core, so 2 jobs use a 2-core machine; default 1)")
    p.add_argument("--report-only", action="store_true",
                   help="train nothing; draw the figures and table from the runs on disk")
    p.add_argument("--dry-run", action="store_true", help="print the plan; train nothing")
    a = p.parse_args(argv)
    if a.preset not in PRESETS:
        p.error(f"unknown --preset {a.preset!r}; expected one of {', '.join(PRESETS)}")
    for name, given, known in (("--tasks", a.tasks, TASKS), ("--algos", a.algos, ALGOS)):
        unknown = [x for x in given if x not in known]
        if unknown:
            p.error(f"unknown {name} {', '.join(map(repr, unknown))}; expected some of "
                    f"{', '.join(known)}")
        if len(set(given)) != len(given):
            p.error(f"{name} lists a value twice: {' '.join(given)}")
    if a.seeds is None:
        a.seeds = DEFAULT_SEEDS.get(a.preset, 6)
    if a.seeds < 1:
        p.error(f"--seeds must be >= 1, got {a.seeds}")
    if a.jobs < 1:
        p.error(f"--jobs must be >= 1, got {a.jobs}")
    if a.report_only and a.dry_run:
        p.error("--report-only and --dry-run contradict each other (one draws, one only plans)")
    try:
        over = parse_overrides(a.set)
    except ValueError as e:
        p.error(str(e))
    clash = sorted(set(over.get("", {})) & set(GRID_FIELDS))
    if clash:
        p.error(f"--set {', '.join(clash)}: the grid sets these itself (use --tasks / --algos / "
                f"--preset / --seeds / --ablations); they contradict it")
    return a, p


def plan(a) -> list[Cell]:
    """Every cell of the grid, its config built (ValueError on a contradiction)."""
    wanted = [(t, v) for t in a.tasks for v in a.algos]
    if a.ablations:
        wanted += [(ABLATION_TASK, v) for v in ABLATIONS if (ABLATION_TASK, v) not in wanted]
    cells = []
    for task, variant in wanted:
        algo, flags = VARIANTS[variant]
        cfg = build_config(task, algo, a.preset, seeds=a.seeds, overrides=a.set, **flags)
        cells.append(Cell(task, variant, cfg, run_dir(a.out, task, variant)))
    return cells


def check_existing(cells: list[Cell], seed: int | None = None) -> None:
    """A run dir that holds another config or base seed (finished or not) is never touched:
    refuse the whole grid before anything runs."""
    for c in cells:
        if os.path.exists(os.path.join(c.out, "config.json")):
            try:
                check_resume(c.out, c.cfg, seed)
            except ValueError as e:
                state = "finished" if is_complete(c.out) else "unfinished"
                raise ValueError(f"{c.out} holds a {state} run made with other settings ({e}); use "
                                 f"another --out or the same settings") from None


def status(c: Cell) -> str:
    if is_complete(c.out):
        return "done"
    return "resume" if os.path.exists(os.path.join(c.out, "config.json")) else "new"


def _grid_dir(run_out: str) -> str:
    """DIR of a run in DIR/runs/TASK__VARIANT."""
    return os.path.dirname(os.path.dirname(run_out))


def seg_dir(c: Cell) -> str:
    return os.path.join(_grid_dir(c.out), "segmentation", c.task)


def pretrain_dir(run_out: str) -> str:
    """DIR/pretrain: pre-training datasets and models the grid's runs share (content-keyed,
    `pretrain.pretrain(cache=...)`): a task's Skew-Fit and ablation runs reuse the scene data
    and scene-VAE its ROLL run trained when their configs match."""
    return os.path.join(_grid_dir(run_out), "pretrain")


def _uses_segmentation(c: Cell) -> bool:
    from roll_jax.encoders.goal_encoding import goal_encoder

    return goal_encoder(c.cfg).segment


def fit_dependencies(cells: list[Cell]) -> dict[str, list[Cell]]:
    """For parallel jobs: a task's segmentation is fitted by the first of its cells that uses
    it; the task's other segmenting cells wait for that cell, so no two jobs fit (or write)
    the same segmentation. Returns cell dir -> the cells waiting for it (only fitters)."""
    fitter: dict[str, Cell] = {}
    for c in cells:
        if (_uses_segmentation(c) and c.task not in fitter
                and not os.path.exists(os.path.join(seg_dir(c), "meta.json"))):
            fitter[c.task] = c
    return {f.out: [c for c in cells if _uses_segmentation(c) and c.task == t and c is not f]
            for t, f in fitter.items()}


def _models_pretrained(c: Cell) -> int:
    """How many encoders a cell pre-trains (scene-VAE, object-VAE, LSTM): its size, roughly."""
    from roll_jax.encoders.goal_encoding import goal_encoder

    enc = goal_encoder(c.cfg)
    return 1 + (enc.object_cfg is not None) + bool(enc.lstm)


def schedule(cells: list[Cell]) -> tuple[list[Cell], dict[str, list[Cell]]]:
    """(cells free to start, in start order; cell dir -> cells it releases). Fitters go first,
    the one releasing the most cells first; a released cell starts next (ahead of the
    queue), so the grid never waits at a barrier for one long cell. The other cells follow
    the largest first (more encoders to pre-train), so no long cell is left to run alone at
    the end."""
    deps = fit_dependencies(cells)
    waiting = {c.out for ws in deps.values() for c in ws}
    fitters = sorted((c for c in cells if c.out in deps), key=lambda c: -len(deps[c.out]))
    rest = sorted((c for c in cells if c.out not in deps and c.out not in waiting),
                  key=lambda c: -_models_pretrained(c))
    return fitters + rest, deps


def _use_cache(path: str) -> None:
    """JAX's persistent compilation cache in DIR/.jax_cache (unless one is configured
    already): cells of one task share their data-collection and pre-training programs, and a
    resumed grid skips its compiles."""
    from roll_jax.training import compiler

    compiler.use(path)


def _run_cell(cfg, out: str, resume: bool, seg_ckpt: str, seed: int, devices, seed_batch,
              progress: bool = False, run_fn=None, cache: str | None = None) -> float:
    """One cell: `train.run` (or a test's stand-in `run_fn`) with the grid's shared
    pre-training; returns its seconds. `cache`: the compilation cache a worker process
    (spawned: a fresh JAX) sets up first."""
    if cache is not None:
        _use_cache(cache)
    if run_fn is None:
        from roll_jax.training import driver

        run_fn = driver.run
    t0 = time.time()
    run_fn(cfg, out, resume=resume, seg_ckpt=seg_ckpt, seed=seed, devices=devices,
           seed_batch=seed_batch, pretrain_cache=pretrain_dir(out), progress=progress)
    return time.time() - t0


def run_grid(cells: list[Cell], a, run_fn=None, pool=None) -> dict[str, str]:
    """Train every cell that is not finished; returns cell dir -> what happened.

    With a.jobs > 1 the cells run in that many worker processes (`pool`: an Executor factory
    taking max_workers; spawned processes by default) in the order of `schedule`."""
    done: dict[str, str] = {}
    todo = []
    for i, c in enumerate(cells):
        what = status(c)
        tag = f"[{i + 1}/{len(cells)}] {c.task} {c.variant} ({c.cfg.seeds} seeds)"
        if what == "done":
            print(f"{tag}: finished before, skipped", flush=True)
            done[c.out] = "skipped"
        else:
            todo.append((c, tag, what))
    jobs = a.jobs
    cache = os.path.join(os.path.abspath(a.out), ".jax_cache")
    if jobs <= 1:
        if run_fn is None:
            _use_cache(cache)
        for c, tag, what in todo:
            print(f"{tag}: {'resuming' if what == 'resume' else 'starting'} in {c.out}", flush=True)
            seconds = _run_cell(c.cfg, c.out, what == "resume", seg_dir(c), a.seed, a.devices,
                                a.seed_batch, progress=True, run_fn=run_fn)
            print(f"{tag}: done in {seconds:.0f} s", flush=True)
            done[c.out] = "resumed" if what == "resume" else "ran"
        return done

    import concurrent.futures as cf
    import functools

    if pool is None:
        import multiprocessing

        pool = functools.partial(cf.ProcessPoolExecutor,
                                 mp_context=multiprocessing.get_context("spawn"))
    run_fn = functools.partial(_run_cell, run_fn=run_fn, cache=cache if run_fn is None else None)
    info = {c.out: (tag, what) for c, tag, what in todo}
    queue, releases = schedule([c for c, _, _ in todo])
    t_grid = time.time()

    def submit(ex, c):
        tag, what = info[c.out]
        print(f"{tag}: starting ({'resume' if what == 'resume' else 'new'}), {c.out}", flush=True)
        return ex.submit(run_fn, c.cfg, c.out, what == "resume", seg_dir(c), a.seed, a.devices,
                         a.seed_batch)

    with pool(max_workers=jobs) as ex:
        running = {}
        while queue or running:
            while queue and len(running) < jobs:  # only `jobs` in flight: released cells can
                c = queue.pop(0)                   # still jump the queue
                running[submit(ex, c)] = c
            finished, _ = cf.wait(running, return_when=cf.FIRST_COMPLETED)
            for fut in finished:
                c = running.pop(fut)
                seconds = fut.result()  # a failed cell stops the grid (finished cells stay)
                tag, what = info[c.out]
                print(f"{tag}: done in {seconds:.0f} s (its own run time; grid at "
                      f"{time.time() - t_grid:.0f} s)", flush=True)
                done[c.out] = "resumed" if what == "resume" else "ran"
                queue[:0] = releases.get(c.out, [])
    return done


# ----------------------------------------------------------------------------- report

PHASES = ("segmentation", "pretrain", "init", "chunks", "final_eval")  # of a run's timings.json


def run_timings(out: str) -> list[dict]:
    """Per run of the grid in `out`: its total and per-phase wall and CPU seconds (its
    timings.json), the first chunk apart (it includes the chunk's compile)."""
    runs = []
    base = os.path.join(out, "runs")
    for name in sorted(os.listdir(base)):
        path = os.path.join(base, name, "timings.json")
        if not os.path.exists(path):
            raise FileNotFoundError(f"{path}: the run has no timings.json (unfinished?)")
        with open(path) as f:
            t = json.load(f)
        wall, cpu = t["wall_s"], t["cpu_s"]
        row = {"run": name, "total_wall_s": t["total_wall_s"], "total_cpu_s": t["total_cpu_s"]}
        for k in PHASES:
            row[f"{k}_wall_s"] = round(sum(wall.get(k, [])), 2)
            row[f"{k}_cpu_s"] = round(sum(cpu.get(k, [])), 2)
        row["first_chunk_wall_s"] = wall["chunks"][0]
        runs.append(row)
    return runs


def timings_summary(runs: list[dict]) -> dict:
    """The sums over `run_timings` rows: runs, their wall and CPU seconds, the first chunks'
    wall seconds, wall seconds per phase."""
    return {"runs": len(runs),
            "sum_run_wall_s": round(sum(r["total_wall_s"] for r in runs), 1),
            "sum_run_cpu_s": round(sum(r["total_cpu_s"] for r in runs), 1),
            "first_chunk_wall_s": round(sum(r["first_chunk_wall_s"] for r in runs), 1),
            "phase_wall_s": {k: round(sum(r[f"{k}_wall_s"] for r in runs), 1) for k in PHASES}}


def read_metrics(path: str) -> list[dict]:
    return read_rows(path, 2**62)  # every row


def seed_auc(rows: list[dict], key: str = METRIC) -> np.ndarray:
    """Per seed, the area under its curve divided by the env steps it spans: the curve's
    trapezoidal mean over training, in the metric's unit (a single evaluation: its value)."""
    aucs = []
    for seed in sorted({r["seed"] for r in rows}):
        pts = sorted((r["env_steps"], r[key]) for r in rows if r["seed"] == seed)
        s, v = np.asarray(pts, dtype=np.float64).T
        aucs.append(v[0] if len(s) == 1 else
                    float(np.sum((v[1:] + v[:-1]) / 2 * np.diff(s)) / (s[-1] - s[0])))
    return np.asarray(aucs)


def final_stats(rows: list[dict], key: str = METRIC) -> dict:
    """median / 25th / 75th percentile over seeds at the last evaluated env step, and of the
    seeds' areas under the curve (`seed_auc`)."""
    steps, med, lo, hi = plots.seed_quantiles(rows, key)
    auc = seed_auc(rows, key)
    return {"env_steps": int(steps[-1]), "seeds": sum(int(r["env_steps"] == steps[-1]) for r in rows),
            "median": float(med[-1]), "q25": float(lo[-1]), "q75": float(hi[-1]),
            "auc_median": float(np.median(auc)), "auc_q25": float(np.percentile(auc, 25)),
            "auc_q75": float(np.percentile(auc, 75))}


def _panels(n: int):
    plt = plots.pyplot()
    cols = min(n, 3)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.3 * rows), squeeze=False)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    return plt, fig, list(axes.flat[:n])


def figure4(curves: dict[str, dict[str, list[dict]]], path: str) -> None:
    """One panel per task; in each, median and 25-75% band over seeds per algorithm."""
    plt, fig, axes = _panels(max(len(curves), 1))
    for ax, (task, by_algo) in zip(axes, curves.items()):
        for variant, rows in by_algo.items():
            if rows:
                plots.plot_median_band(ax, rows, LABELS.get(variant, variant),
                                       color=COLORS.get(variant))
        if not any(by_algo.values()):
            ax.text(0.5, 0.5, "no results yet", ha="center", va="center", transform=ax.transAxes)
        ax.set_title(task)
        ax.legend(fontsize=7)
    fig.suptitle("final distance to goal: median over seeds, band 25-75%", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def ablation_figure(by_variant: dict[str, list[dict]], path: str) -> None:
    plt, fig, (ax,) = _panels(1)
    for variant, rows in by_variant.items():
        if rows:
            plots.plot_median_band(ax, rows, LABELS.get(variant, variant),
                                   color=COLORS.get(variant))
    ax.set_title(f"ablations on {ABLATION_TASK} (median, 25-75%)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


TABLE_FIELDS = ("task", "algo", "env_steps", "seeds", "median", "q25", "q75", "auc_median",
                "auc_q25", "auc_q75", "complete")


def results_table(entries: list[dict], out: str) -> None:
    """DIR/results.csv and DIR/results.md: final distance and area under the curve per task /
    algorithm."""
    with open(os.path.join(out, "results.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=TABLE_FIELDS)
        w.writeheader()
        w.writerows(entries)
    lines = [f"# Final distance to goal ({METRIC}, lower is better)", "",
             "Median and 25th-75th percentile over seeds at the last evaluation of each run; "
             "area under the curve: per seed, the curve's trapezoidal mean over the env steps "
             "it spans (same unit; lower is better), median and 25th-75th percentile over seeds.",
             "",
             "| task | algorithm | env steps | seeds | median | 25% | 75% | AUC median | AUC 25% "
             "| AUC 75% | complete |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for e in entries:
        lines.append(f"| {e['task']} | {LABELS.get(e['algo'], e['algo'])} | {e['env_steps']} | "
                     f"{e['seeds']} | {e['median']:.4f} | {e['q25']:.4f} | {e['q75']:.4f} | "
                     f"{e['auc_median']:.4f} | {e['auc_q25']:.4f} | {e['auc_q75']:.4f} | "
                     f"{'yes' if e['complete'] else 'no'} |")
    with open(os.path.join(out, "results.md"), "w") as f:
        f.write("\n".join(lines) + "\n")


def report(cells: list[Cell], out: str, ablations: bool) -> list[dict]:
    """Figures and table from whatever metrics.csv the cells have (missing ones: left out)."""
    rows_of = {}
    for c in cells:
        path = os.path.join(c.out, "metrics.csv")
        rows_of[(c.task, c.variant)] = read_metrics(path) if os.path.exists(path) else []
    main = [c for c in cells if c.variant in ALGOS]
    curves: dict[str, dict[str, list[dict]]] = {}
    for c in main:
        curves.setdefault(c.task, {})[c.variant] = rows_of[(c.task, c.variant)]
    os.makedirs(out, exist_ok=True)
    if curves:
        figure4(curves, os.path.join(out, "figure4.png"))
    if ablations:
        ablation_figure({v: rows_of.get((ABLATION_TASK, v), []) for v in ABLATIONS},
                        os.path.join(out, "ablations.png"))
    entries = []
    for c in cells:
        rows = rows_of[(c.task, c.variant)]
        if rows:
            entries.append({"task": c.task, "algo": c.variant, **final_stats(rows),
                            "complete": is_complete(c.out)})
    results_table(entries, out)
    return entries


def main(argv=None, run_fn=None, pool=None) -> int:
    a, p = parse_args(argv)
    try:
        cells = plan(a)
        check_existing(cells, a.seed)
        if not (a.report_only or a.dry_run):
            from roll_jax.training import sharding

            devs = sharding.resolve(a.devices, a.seeds)
            sharding.resolve_seed_batch(a.seed_batch, a.seeds, len(devs))
    except (ValueError, TypeError) as e:
        p.error(str(e))
    if a.dry_run:
        for c in cells:
            print(f"{status(c):6s} {c.task} {c.variant} -> {c.out}")
        return 0
    os.makedirs(a.out, exist_ok=True)
    if not a.report_only:
        from roll_jax.common.checkpoint import DamagedCheckpoint
        from roll_jax.training import events, run_dir

        try:
            run_grid(cells, a, run_fn, pool)
        except (run_dir.RunLocked, events.EventDirNotWritable, DamagedCheckpoint) as e:
            # a cell another process trains, or that cannot go on (finished cells stay)
            print(f"error: {e}", file=sys.stderr, flush=True)
            return 1
    entries = report(cells, a.out, a.ablations)
    print(json.dumps({"out": a.out, "results": entries}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
