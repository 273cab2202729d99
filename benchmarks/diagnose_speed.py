"""Deployment benchmarks: ``bayes-fdi diagnose`` speed and memory, model round trips, simulate on
workers, against their targets.

    .venv/bin/python benchmarks/diagnose_speed.py [--model FILE | --stand-in] [--only ...]

- ``day``: one day of 1 Hz data (the shipped Lublin hour tiled 24 times, with two 60-s gaps)
  diagnosed by ``bayes-fdi diagnose`` in a child process pinned to one CPU, single-threaded;
  target <= 10 s. Also the diagnoser's ``run`` alone.
- ``year``: ``--year-days`` days (default 365, 31.5 M samples) written as a chunked netCDF file,
  diagnosed lazily by ``bayes-fdi diagnose``; the child's peak RSS; target <= 4 GB.
- ``roundtrip``: save and load a fitted paper ``FaultDiagnoser`` and the online model; the outputs
  after loading must equal the saved model's bit for bit.
- ``simulate``: ``bayes-fdi simulate`` of a campaign, multi-threaded in one process against
  ``--workers 2`` (with the cluster's start, and on a running cluster), alternated, medians;
  target: workers within 1.1x.

The model: ``--model FILE`` (from ``bayes-fdi fit``), by default the cached default model
(fitted on first use). ``--stand-in`` uses the tests' stand-in online diagnoser
(``tests/stream_double.py``: linear normal models and a CUSUM) to measure the pipeline's own
cost (reading, chunking, writing the files, the figure) without the real diagnoser: its figures
are not the targets'. The machine is shared: the load average is printed with every result.
Results go to stdout and ``benchmarks/out/diagnose_speed.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SINGLE = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
          "NUMBA_NUM_THREADS": "1"}  # fmt: skip
CHANNELS = ("CV", "P1", "P2", "T1", "X", "F")


def _load() -> str:
    return " ".join(f"{x:.1f}" for x in os.getloadavg())


def _child(argv: list[str], *, stand_in: bool, env: dict | None = None, cpus=None) -> dict:
    """Run ``bayes-fdi ARGV`` in a child process; wall, CPU and peak RSS of the child."""
    prelude = "import sys\n"
    if stand_in:
        prelude += f"sys.path.insert(0, {str(ROOT / 'tests')!r}); import stream_double\n"
    if cpus is not None:
        prelude += f"import os; os.sched_setaffinity(0, {set(cpus)!r})\n"
    code = prelude + f"from bayes_fdi.cli import main\nsys.exit(main({argv!r}))\n"
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", code], env={**os.environ, **(env or {})},
                          capture_output=True, text=True)  # fmt: skip
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise RuntimeError(f"bayes-fdi {' '.join(argv)} failed:\n{done.stderr[-3000:]}")
    return {
        "wall_s": wall,
        "cpu_s": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
        "peak_rss_mb": after.ru_maxrss / 1024.0,  # the largest child so far (kB on Linux)
        "stdout": done.stdout.strip().splitlines()[-2:],
    }


# ----------------------------------------------------------------------------------------------
# recordings
# ----------------------------------------------------------------------------------------------
def _hour() -> dict[str, np.ndarray]:
    from bayes_fdi.datasets import load_lublin_example

    hour = load_lublin_example()
    return {c: hour[c].values[0] for c in CHANNELS}


def write_days(path: Path, days: int) -> float:
    """A netCDF recording of ``days`` x 86 400 s (the real hour tiled), written day by day."""
    import netCDF4

    hour = _hour()
    t0 = time.perf_counter()
    with netCDF4.Dataset(path, "w") as nc:
        nc.createDimension("time", None)
        time_var = nc.createVariable("time", "f8", ("time",), chunksizes=(86_400,))
        time_var.units = "s"
        variables = {c: nc.createVariable(c, "f8", ("time",), zlib=True, complevel=1,
                                          chunksizes=(86_400,)) for c in CHANNELS}  # fmt: skip
        for d in range(days):
            a = d * 86_400
            time_var[a : a + 86_400] = np.arange(a, a + 86_400, dtype=np.float64)
            for c in CHANNELS:
                values = np.tile(hour[c], 24)
                if d == 0 and c == "X":
                    values[40_000:40_060] = np.nan  # two gaps: BLIND seconds
                    values[70_000:70_060] = np.nan
                variables[c][a : a + 86_400] = values
    return time.perf_counter() - t0


def model_file(args, work: Path) -> tuple[str, object]:
    """The model file to benchmark (written for the stand-in) and the loaded model."""
    from bayes_fdi import model_files

    if args.stand_in:
        sys.path.insert(0, str(ROOT / "tests"))
        import xarray as xr
        from stream_double import StreamDouble

        from bayes_fdi.datasets import load_lublin_example

        model = StreamDouble().fit(xr.concat([load_lublin_example()], dim="run"))
        path = work / "stand-in.npz"
        model_files.save(model, path)
        return str(path), model
    if args.model:
        from bayes_fdi.deployment.fitting import load_online_model

        return args.model, load_online_model(args.model)
    from bayes_fdi.deployment.fitting import default_model, default_model_path

    model = default_model(progress=True)
    return str(default_model_path()), model


# ----------------------------------------------------------------------------------------------
# benchmarks
# ----------------------------------------------------------------------------------------------
def bench_day(args, work: Path, model_path: str, model) -> dict:
    import torch
    import xarray as xr

    path = work / "day.nc"
    write_days(path, 1)
    runs = []
    for k in range(args.repeats):
        out = work / f"day-out-{k}"
        runs.append(_child(["diagnose", str(path), "--model", model_path, "--out", str(out),
                            "--quiet"], stand_in=args.stand_in, env=SINGLE, cpus=[0]))  # fmt: skip
    torch.set_num_threads(1)
    with xr.open_dataset(path) as opened:
        day = opened.load().expand_dims(run=[0]).transpose("run", "time")
    start = time.process_time()
    model.run(day)
    run_cpu = time.process_time() - start
    best = min(runs, key=lambda r: r["wall_s"])
    return {
        "what": "bayes-fdi diagnose of one day (86 400 s), one CPU, one thread",
        "wall_s_runs": [r["wall_s"] for r in runs],
        "wall_s_best": best["wall_s"],
        "cpu_s_best": min(r["cpu_s"] for r in runs),
        "peak_rss_mb": max(r["peak_rss_mb"] for r in runs),
        "diagnoser_run_cpu_s": run_cpu,
        "target_s": 10.0,
        "load": _load(),
        "output": best["stdout"],
    }


def bench_year(args, work: Path, model_path: str) -> dict:
    path = work / "year.nc"
    write_s = write_days(path, args.year_days)
    out = work / "year-out"
    res = _child(["diagnose", str(path), "--model", model_path, "--out", str(out), "--quiet"],
                 stand_in=args.stand_in, env=SINGLE)  # fmt: skip
    sizes = {p.name: p.stat().st_size for p in (out / "year").iterdir()}
    return {
        "what": f"bayes-fdi diagnose of {args.year_days} days ({args.year_days * 86_400} samples), "
        "read lazily in 1-day chunks",
        "write_input_s": write_s,
        "input_mb": path.stat().st_size / 1e6,
        "wall_s": res["wall_s"],
        "cpu_s": res["cpu_s"],
        "peak_rss_mb": res["peak_rss_mb"],
        "target_peak_mb": 4096,
        "output_mb": {k: v / 1e6 for k, v in sizes.items()},
        "load": _load(),
    }


def bench_roundtrip(args, work: Path, model) -> dict:
    import torch
    import xarray as xr

    from bayes_fdi import model_files
    from bayes_fdi.campaigns.shipped import campaign_path
    from bayes_fdi.campaigns.simulation import simulate_campaign
    from bayes_fdi.datasets import load_lublin_example
    from bayes_fdi.diagnosis import FaultDiagnoser
    from bayes_fdi.diagnosis.seva.record import to_frame

    torch.set_num_threads(1)
    from bayes_fdi.campaigns.parsing import load_campaign

    campaign = load_campaign(campaign_path("paper-simulated"), runs_per_state=6,
                             states=["fn", "f1", "f2", "f17", "f18"])  # fmt: skip
    runs = simulate_campaign(campaign, progress=False)
    normal = runs.isel(run=np.flatnonzero(runs["state"].values == "fn"))
    out = {}
    t0 = time.perf_counter()
    offline = FaultDiagnoser(max_train_samples=1000).fit(normal, runs)
    fit_s = time.perf_counter() - t0
    for name, obj, check in (
        ("FaultDiagnoser (paper, RVM tree)", offline,
         lambda m: (m.diagnose(runs), to_frame(m.seva(runs)))),
        (f"online model ({type(model).__name__})", model,
         lambda m: (m.run(load_lublin_example()),)),
    ):  # fmt: skip
        path = work / "roundtrip.npz"
        t0 = time.perf_counter()
        model_files.save(obj, path)
        save_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        back = model_files.load(path)
        load_s = time.perf_counter() - t0
        exact = True
        for a, b in zip(check(obj), check(back), strict=True):
            if isinstance(a, xr.Dataset):
                exact &= a.identical(b)
            else:
                exact &= bool(a.equals(b))
        out[name] = {"save_s": save_s, "load_s": load_s, "size_mb": path.stat().st_size / 1e6,
                     "outputs_identical": bool(exact)}  # fmt: skip
    out["fit_s (FaultDiagnoser)"] = fit_s
    out["load"] = _load()
    return out


def bench_simulate(args, work: Path) -> dict:
    from bayes_fdi.campaigns.shipped import campaign_path
    from bayes_fdi.distributed import cluster_client

    toml = str(campaign_path(args.campaign))
    base = ["simulate", toml, "--out", str(work / "sim.nc"), "--quiet"]
    threaded_env = {k: v for k, v in os.environ.items() if k not in SINGLE}
    rows: dict[str, list[float]] = {"threads": [], "workers": [], "running cluster": []}
    with cluster_client(workers=2) as client:
        address = client.scheduler.address
        for _ in range(args.repeats):
            rows["threads"].append(_child_wall(base, threaded_env))
            rows["workers"].append(_child_wall([*base, "--workers", "2"], threaded_env))
            rows["running cluster"].append(
                _child_wall([*base, "--scheduler", address], threaded_env)
            )
    med = {k: statistics.median(v) for k, v in rows.items()}
    return {
        "what": f"bayes-fdi simulate {args.campaign}: multi-threaded process vs 2 workers",
        "wall_s": rows,
        "median_wall_s": med,
        "ratio_workers_vs_threads": med["workers"] / med["threads"],
        "ratio_running_cluster_vs_threads": med["running cluster"] / med["threads"],
        "target_ratio": 1.1,
        "load": _load(),
    }


def _child_wall(argv: list[str], env: dict) -> float:
    start = time.perf_counter()
    code = f"import sys\nfrom bayes_fdi.cli import main\nsys.exit(main({argv!r}))\n"
    subprocess.run([sys.executable, "-c", code], env=env, check=True, capture_output=True)
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--model", help="model file (bayes-fdi fit); default: the default model")
    which.add_argument("--stand-in", action="store_true", help="the tests' stand-in diagnoser")
    parser.add_argument("--only", default="day,roundtrip,simulate,year",
                        help="comma-separated: day, year, roundtrip, simulate")  # fmt: skip
    parser.add_argument("--year-days", type=int, default=365)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--campaign", default="paper-simulated")
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "out"))
    args = parser.parse_args(argv)
    chosen = [w.strip() for w in args.only.split(",") if w.strip()]
    model_name = "stand-in" if args.stand_in else (args.model or "default")
    results: dict = {"machine": f"{platform.node()} {os.cpu_count()} CPUs", "load": _load(),
                     "model": model_name}  # fmt: skip
    work = Path(tempfile.mkdtemp(prefix="diagnose-speed-"))
    try:
        model_path, model = (None, None)
        if {"day", "year", "roundtrip"} & set(chosen):
            model_path, model = model_file(args, work)
        for name in chosen:
            print(f"== {name} (load {_load()})", flush=True)
            if name == "day":
                results[name] = bench_day(args, work, model_path, model)
            elif name == "year":
                results[name] = bench_year(args, work, model_path)
            elif name == "roundtrip":
                results[name] = bench_roundtrip(args, work, model)
            elif name == "simulate":
                results[name] = bench_simulate(args, work)
            else:
                parser.error(f"unknown benchmark {name!r}")
            print(json.dumps(results[name], indent=2), flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    Path(args.out).mkdir(parents=True, exist_ok=True)
    target = Path(args.out) / "diagnose_speed.json"
    target.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {target}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
