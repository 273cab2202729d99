"""Load of ``bayes-fdi serve``: many valves at 1 Hz from a simulated plant on the loopback.

Starts ``bayes-fdi serve`` (one process, every valve) and ``bayes-fdi simulate-plant`` (real
time, ``--wait-subscribed``: its first second is written once serve's subscription holds every
node; ``--write-times``) on 127.0.0.1, samples the serve process's CPU time and memory (psutil)
every second, stops both, and reads the valves' logs:

- end-to-end latency of each record: its ``published`` time (serve wrote it to its OPC UA
  server) minus the time the plant simulator finished writing that valve's samples of that
  second; split into the delivery (the valve's last sample of the second received by serve)
  and serve's own part (received to published);
- missed seconds: seconds of the plant's run that are BLIND or absent in the log, other than
  the plant's last second (whose samples may arrive after it stopped) and the seconds of a
  scheduled outage (``--outage START SECONDS``, reported apart: the BLIND seconds in it per
  valve, and the valves whose DD rises from its start to 60 s after it while the model detects
  nothing there on the same simulated plant without the outage: alarms the outage raised);
- CPU (% of one core) and resident memory of serve, in all and per valve (and its growth over
  the run); the load average.

    python benchmarks/serve_load.py --valves 200 --seconds 600
    python benchmarks/serve_load.py --valves 20 --seconds 120 --outage 40 5

The target: 200 valves, median latency <= 100 ms, no missed second over 10 minutes.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

FAULTS = ("f1", "f7", "f18")


def _toml(path: Path, n: int, seconds: int, ports: tuple[int, int], outage=None) -> None:
    lines = [
        "[plant]",
        f'endpoint = "opc.tcp://127.0.0.1:{ports[0]}/plant"',
        "publishing_interval = 0.02",
        "reconnect_min = 0.1",
        "reconnect_max = 0.5",
        "[server]",
        f'endpoint = "opc.tcp://127.0.0.1:{ports[1]}/seva"',
        'security = ["None"]',
        "allow_anonymous = true",
        "[log]",
        'folder = "log"',
        "[simulation]",
        f"duration = {seconds}",
        "seed = 3",
    ]
    if outage:
        lines.append(f"outages = [{{start = {outage[0]}, seconds = {outage[1]}}}]")
    for i in range(n):
        lines.append(f"[valves.V{i:03d}]")
        if i % 10 == 0:  # a tenth of the valves develop a fault half-way
            f = FAULTS[(i // 10) % 3]
            lines.append(f'fault = {{name = "{f}", strength = 0.6, onset = {seconds // 2}}}')
    path.write_text("\n".join(lines) + "\n")


def _popen(args: list[str], cwd: Path) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1")
    return subprocess.Popen(
        [sys.executable, "-m", "bayes_fdi", *args],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def _wait_line(proc: subprocess.Popen, text: str, lines: list[str]) -> str:
    for line in proc.stdout:
        lines.append(line)
        if text in line:
            threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True).start()
            return line
    raise RuntimeError("".join(lines[-30:]))


def main(argv: list[str] | None = None) -> int:
    import psutil

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--valves", type=int, default=200)
    parser.add_argument("--seconds", type=int, default=600)
    parser.add_argument("--model", default=None, help="model file (default: a small fit)")
    parser.add_argument("--folder", default=None, help="work folder (default: a temporary one)")
    parser.add_argument(
        "--outage", type=int, nargs=2, default=None, metavar=("START", "SECONDS"),
        help="the plant server is down for SECONDS from plant second START",
    )  # fmt: skip
    args = parser.parse_args(argv)
    folder = Path(args.folder or tempfile.mkdtemp(prefix="serve-load-"))
    folder.mkdir(parents=True, exist_ok=True)
    from tests.serve_helpers import fit_tiny_model, free_ports

    model = Path(args.model).resolve() if args.model else fit_tiny_model(folder / "tiny.npz")
    ports = tuple(free_ports(2))
    _toml(folder / "valve.toml", args.valves, args.seconds, ports, args.outage)
    load_before = os.getloadavg()
    serve_lines: list[str] = []
    serve = _popen(["serve", "--config", "valve.toml", "--model", str(model)], folder)
    _wait_line(serve, "serve:", serve_lines)
    plant_lines: list[str] = []
    plant = _popen(
        ["simulate-plant", "--config", "valve.toml", "--write-times", "writes.csv",
         "--wait-subscribed"], folder,
    )  # fmt: skip
    start = float(_wait_line(plant, "from plant time", plant_lines).split("plant time ")[1])
    ps = psutil.Process(serve.pid)
    cpu0, t0 = ps.cpu_times(), time.monotonic()
    samples = []
    while plant.poll() is None:
        time.sleep(1.0)
        samples.append((time.monotonic(), sum(ps.cpu_times()[:2]), ps.memory_info().rss))
    cpu1, t1 = ps.cpu_times(), time.monotonic()
    load_after = os.getloadavg()
    time.sleep(2.0)
    serve.send_signal(signal.SIGTERM)
    serve.wait(300)
    print(f"load average before {load_before}, after {load_after} (2-core machine)")
    report(folder, args, start, (cpu0, cpu1, t0, t1), samples)
    return 0


def _percentiles(x: np.ndarray) -> str:
    return (
        f"median {np.median(x):.1f}, p95 {np.percentile(x, 95):.1f}, "
        f"p99 {np.percentile(x, 99):.1f}, max {x.max():.1f}"
    )


def report(folder: Path, args, start: float, cpu, samples) -> None:
    """Print the measurements (see the module docstring)."""
    import pandas as pd

    from bayes_fdi.deployment.serve.durable_log import read_log

    n, seconds = args.valves, args.seconds
    writes = pd.read_csv(folder / "writes.csv")
    outage = set(range(args.outage[0], sum(args.outage))) if args.outage else set()
    clean_dd = _clean_dd(folder, args) if outage else None
    total, deliver, own = [], [], []
    missed = records = raised = 0
    blind_in_outage = []
    for i in range(n):
        name = f"V{i:03d}"
        log = read_log(folder / "log", name)
        k = log["time"].values.astype("datetime64[s]").astype(np.int64) - int(start)
        inside = (k >= 0) & (k < seconds - 1)
        status = log["status"].values
        records += int(inside.sum())
        in_outage = np.isin(k, list(outage))
        blind_in_outage.append(int((status[inside & in_outage] == "BLIND").sum()))
        missed += int((status[inside & ~in_outage] == "BLIND").sum())
        missed += (seconds - 1 - len(outage)) - int((inside & ~in_outage).sum())
        if outage:
            raised += _raised(log["DD"].values[inside], k[inside], clean_dd[i], outage)
        w = writes[writes["valve"] == name].set_index("k")["written"]
        ok = inside & np.isin(k, w.index)
        written = w.reindex(k[ok]).values
        total.append(log["published"].values[ok] - written)
        received = log["received"].values[ok]
        has = np.isfinite(received)
        deliver.append(received[has] - written[has])
        own.append(log["published"].values[ok][has] - received[has])
    lat, dl, sv = (np.concatenate(x) * 1000.0 for x in (total, deliver, own))
    cpu0, cpu1, t0, t1 = cpu
    used = (cpu1.user + cpu1.system) - (cpu0.user + cpu0.system)
    percent = 100.0 * used / (t1 - t0)
    rss = max(s[2] for s in samples) / 2**20
    print(f"valves {n}, plant seconds {seconds} (real time), records {records}")
    print(f"latency ms (plant wrote the valve's second -> serve published it): {_percentiles(lat)}")
    print(f"  of which plant -> serve (last sample received): {_percentiles(dl)}")
    print(f"  of which serve (received -> published): {_percentiles(sv)}")
    print(f"missed seconds (BLIND or absent, all valves, outside outages): {missed}")
    if outage:
        print(
            f"outage of {len(outage)} s from plant second {min(outage)}: BLIND seconds in it per "
            f"valve {sorted(set(blind_in_outage))}; valves whose DD rises in it or the 60 s "
            f"after it, without a detection there in the same plant without the outage: {raised}"
        )
    print(f"serve CPU: {percent:.1f} % of one core in all, {percent / n:.3f} % per valve")
    print(
        f"serve memory (peak RSS): {rss:.0f} MiB in all, {rss / n:.2f} MiB per valve "
        "(including the interpreter and libraries)"
    )
    marks = [(i, samples[i][2] / 2**20) for i in sorted({0, min(59, len(samples) - 1)})]
    marks.append((len(samples) - 1, samples[-1][2] / 2**20))
    print("serve RSS over the run: " + ", ".join(f"{m:.0f} MiB at {i + 1} s" for i, m in marks))


def _clean_dd(folder: Path, args) -> np.ndarray:
    """DD ``(valves, seconds)`` of the simulated plant's recording without the outage."""
    from bayes_fdi.deployment.serve.config import load_config
    from bayes_fdi.deployment.serve.plant_simulator import plant_recording
    from bayes_fdi.diagnosis import OnlineDiagnoser

    config = load_config(str(folder / "valve.toml"), publishing=False)
    model = args.model or str(folder / "tiny.npz")
    stream = OnlineDiagnoser.load(model).run(plant_recording(config, args.seconds))
    return np.asarray(stream["DD"].transpose("run", "time").values)


def _raised(dd: np.ndarray, k: np.ndarray, clean: np.ndarray, outage: set[int]) -> int:
    """1 if DD rises from the outage's start to 60 s after it while the run without the outage
    has no detection in that window (an alarm the outage raised), else 0."""
    window = (k >= min(outage)) & (k < max(outage) + 61)
    rising = dd & ~np.concatenate([[False], dd[:-1]])
    clean_window = clean[min(outage) : min(max(outage) + 61, clean.size)]
    return int(bool((rising & window).any()) and not clean_window.any())


if __name__ == "__main__":
    sys.exit(main())
