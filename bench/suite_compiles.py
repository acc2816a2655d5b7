"""Where `make test`'s time goes: every XLA compile of the test suite, and each test file's
time, by test file.

Runs the suite as `make test` does (two xdist workers, whole files per worker, the empty
compilation cache of a clean clone) with this module as a pytest plugin: it turns on
`jax_log_compiles` and logs each compile, with the test that caused it, and when each test
started and ended, to files per worker. Then it sums them up:
- each file's worker and its span on that worker (first test's start to last test's end,
  setup and fixtures included), and when each worker finished;
- XLA compile seconds per test file;
- programs whose persistent-cache key was compiled more than once (in both workers, or twice in
  one), i.e. what a shared compilation cache could still save within one run.

Compiles inside subprocesses (tests/test_sharding.py's two-device run) are not logged.

    python bench/suite_compiles.py               # ~15-25 min on 2 cores
    python bench/suite_compiles.py --logs DIR    # only sum up the logs of an earlier run

Writes bench/results/suite_compiles.json.
"""
from __future__ import annotations

import argparse
import collections
import glob
import logging
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RESULTS = os.path.join(ROOT, "bench", "results", "suite_compiles.json")
LOG_DIR_ENV = "ROLL_SUITE_COMPILE_LOGS"
_COMPILED = re.compile(r"Finished XLA compilation of (.*) in ([\d.e+-]+) sec")
_MISS = re.compile(r"CACHE MISS for '(.*)' with key '(.*)'")

# ----------------------------------------------------------------------------- the plugin
# Active only when pytest loads this module with -p and the log folder is set.

_current = ["<collection>"]
_log = None
_timeline = None


def pytest_configure(config):
    global _log, _timeline
    folder = os.environ.get(LOG_DIR_ENV)
    if not folder or _log is not None:
        return
    import jax

    jax.config.update("jax_log_compiles", True)
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    _log = open(os.path.join(folder, f"compiles_{worker}.tsv"), "a", buffering=1)
    _timeline = open(os.path.join(folder, f"timeline_{worker}.tsv"), "a", buffering=1)

    class Handler(logging.Handler):
        def emit(self, record):
            msg = record.getMessage().splitlines()[0]
            if _COMPILED.search(msg) or _MISS.search(msg):
                _log.write(f"{time.time():.1f}\t{_current[0]}\t{msg[:300]}\n")

    handler = Handler(level=logging.DEBUG)
    for name in ("jax._src.dispatch", "jax._src.interpreters.pxla", "jax._src.compiler",
                 "jax._src.compilation_cache"):
        logger = logging.getLogger(name)
        logger.addHandler(handler)
        logger.setLevel(logging.DEBUG)


def pytest_runtest_setup(item):
    _current[0] = item.nodeid


def pytest_runtest_logstart(nodeid, location):
    if _timeline is not None:
        _timeline.write(f"{time.time():.3f}\tstart\t{nodeid}\n")


def pytest_runtest_logfinish(nodeid, location):
    if _timeline is not None:
        _timeline.write(f"{time.time():.3f}\tend\t{nodeid}\n")


# ----------------------------------------------------------------------------- the summary

def file_spans(folder: str) -> dict:
    """Each test file's worker and span (seconds from the first test's start in any worker),
    and each worker's finishing time, from the timeline logs."""
    spans, t0 = {}, None
    for path in sorted(glob.glob(os.path.join(folder, "timeline_*.tsv"))):
        worker = os.path.basename(path)[len("timeline_"):-len(".tsv")]
        with open(path) as f:
            for line in f:
                t, _, nodeid = line.rstrip("\n").split("\t", 2)
                t, name = float(t), nodeid.split("::")[0]
                t0 = t if t0 is None else min(t0, t)
                span = spans.setdefault(name, [worker, t, t])
                span[1], span[2] = min(span[1], t), max(span[2], t)
    if not spans:
        return {}
    per_file = {name: {"worker": w, "start_s": round(a - t0, 1), "end_s": round(b - t0, 1),
                       "s": round(b - a, 1)}
                for name, (w, a, b) in sorted(spans.items(), key=lambda kv: kv[1][1])}
    ends: dict[str, float] = {}
    for v in per_file.values():
        ends[v["worker"]] = max(ends.get(v["worker"], 0.0), v["end_s"])
    return {"file_wall_s": per_file, "worker_end_s": ends}


def summarise(folder: str) -> dict:
    """Compile seconds per test file and the keys compiled more than once, from the logs."""
    per_file, worker_of = collections.defaultdict(float), {}
    by_key: dict[str, list] = collections.defaultdict(list)
    files = sorted(glob.glob(os.path.join(folder, "compiles_*.tsv")))
    if not files:
        raise SystemExit(f"no compiles_*.tsv logs in {folder}")
    for path in files:
        worker = os.path.basename(path)[len("compiles_"):-len(".tsv")]
        pending = None
        with open(path) as f:
            for line in f:
                _, test, msg = line.rstrip("\n").split("\t", 2)
                test_file = test.split("::")[0]
                miss = _MISS.search(msg)
                if miss:
                    pending = miss.groups()
                    continue
                done = _COMPILED.search(msg)
                if done:
                    secs = float(done.group(2))
                    per_file[test_file] += secs
                    worker_of[test_file] = worker
                    if pending:
                        by_key[pending[1]].append((worker, test_file, pending[0], secs))
                        pending = None
    repeated = {k: v for k, v in by_key.items() if len(v) > 1}
    return {
        "compile_s_total": round(sum(per_file.values()), 1),
        "compile_s_per_file": {k: {"s": round(v, 1), "worker": worker_of[k]} for k, v in
                               sorted(per_file.items(), key=lambda kv: -kv[1])},
        "programs_compiled": sum(len(v) for v in by_key.values()),
        "keys_compiled_more_than_once": len(repeated),
        "repeat_compile_s": round(sum(sum(x[3] for x in v[1:]) for v in repeated.values()), 1),
        "largest_repeats": [
            {"program": v[0][2], "compiles": [[w, f, round(s, 2)] for w, f, _, s in v]}
            for v in sorted(repeated.values(), key=lambda v: -sum(x[3] for x in v[1:]))[:10]],
    }


def main() -> None:
    sys.path.insert(0, ROOT)
    from bench.common import cpu_model, write_results

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", help="sum up the compiles_*.tsv logs in this folder; no run")
    a = ap.parse_args()
    res = {"what": __doc__.split("\n\n")[0], "cpu_model": cpu_model()}
    folder = a.logs
    if folder is None:
        folder = tempfile.mkdtemp(prefix="suite_compiles_")
        cache = tempfile.mkdtemp(prefix="suite_cache_")  # a clean clone's empty cache
        env = dict(os.environ, **{LOG_DIR_ENV: folder, "PYTHONPATH": ROOT})
        cmd = [sys.executable, "-m", "pytest", "-q", "-n", "2", "--dist", "loadfile",
               "--no-loadscope-reorder", "-p", "bench.suite_compiles",
               "-o", f"cache_dir={cache}"]
        # tests/conftest.py keeps its cache in ROOT/.jax_cache: move it aside for the run.
        jax_cache = os.path.join(ROOT, ".jax_cache")
        kept = jax_cache + ".kept"
        if os.path.exists(jax_cache):
            os.rename(jax_cache, kept)
        t0, c0 = time.perf_counter(), os.times()
        try:
            proc = subprocess.run(cmd, cwd=ROOT, env=env)
        finally:
            if os.path.exists(kept):
                shutil.rmtree(jax_cache, ignore_errors=True)
                os.rename(kept, jax_cache)
        c1 = os.times()
        res.update(pytest_returncode=proc.returncode,
                   wall_s=round(time.perf_counter() - t0, 1),
                   children_cpu_s=round(c1.children_user + c1.children_system
                                        - c0.children_user - c0.children_system, 1))
    res["logs"] = folder
    res.update(file_spans(folder))
    res.update(summarise(folder))
    for k, v in res.get("file_wall_s", {}).items():
        print(f"  {v['s']:7.1f} s  {v['worker']:4s} {v['start_s']:6.1f}-{v['end_s']:6.1f}  {k}")
    for k, v in res["compile_s_per_file"].items():
        print(f"  {v['s']:7.1f} s  {v['worker']:4s} {k}")
    print(f"compiles {res['compile_s_total']} s in all; compiled more than once: "
          f"{res['keys_compiled_more_than_once']} keys, {res['repeat_compile_s']} s")
    write_results(RESULTS, res)


if __name__ == "__main__":
    main()
