"""Load of ``bayes-fdi serve``: many valves at 1 Hz from a simulated plant on the loopback.

Starts ``bayes-fdi serve`` (one process, every valve) and then ``bayes-fdi simulate-plant`` (real
time, ``--write-times``) on 127.0.0.1, samples the serve process's CPU time and memory (psutil)
every second, stops both, and reads the valves' logs:

- end-to-end latency of each record: its ``published`` time (serve wrote it to its OPC UA
  server) minus the time the plant simulator finished writing that second's samples;
- missed seconds: seconds of the plant's run that are not CLEAR/BLURRED/DAZZLED in the log
  (BLIND), other than the plant's last second (whose samples may arrive after it stopped);
- CPU (% of one core) and resident memory of serve, in all and per valve.

    python benchmarks/serve_load.py --valves 200 --seconds 600

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


def _toml(path: Path, n: int, seconds: int, ports: tuple[int, int]) -> None:
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
    faults = ("f1", "f7", "f18")
    for i in range(n):
        lines.append(f"[valves.V{i:03d}]")
        if i % 10 == 0:  # a tenth of the valves develop a fault half-way
            f = faults[(i // 10) % 3]
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
    args = parser.parse_args(argv)
    folder = Path(args.folder or tempfile.mkdtemp(prefix="serve-load-"))
    folder.mkdir(parents=True, exist_ok=True)
    from tests.serve_helpers import fit_tiny_model, free_ports

    model = Path(args.model) if args.model else fit_tiny_model(folder / "tiny.npz")
    _toml(folder / "valve.toml", args.valves, args.seconds, tuple(free_ports(2)))
    serve_lines: list[str] = []
    serve = _popen(["serve", "--config", "valve.toml", "--model", str(model)], folder)
    _wait_line(serve, "serve:", serve_lines)
    plant_lines: list[str] = []
    plant = _popen(
        ["simulate-plant", "--config", "valve.toml", "--write-times", "writes.csv"], folder
    )
    start = float(_wait_line(plant, "simulated plant:", plant_lines).split("plant time ")[1])
    ps = psutil.Process(serve.pid)
    cpu0, t0 = ps.cpu_times(), time.monotonic()
    samples = []
    while plant.poll() is None:
        time.sleep(1.0)
        samples.append((time.monotonic(), sum(ps.cpu_times()[:2]), ps.memory_info().rss))
    cpu1, t1 = ps.cpu_times(), time.monotonic()
    time.sleep(2.0)
    serve.send_signal(signal.SIGTERM)
    serve.wait(120)
    report(folder, args.valves, args.seconds, start, (cpu0, cpu1, t0, t1), samples)
    return 0


def report(folder: Path, n: int, seconds: int, start: float, cpu, samples) -> None:
    """Print the measurements (see the module docstring)."""
    import pandas as pd

    from bayes_fdi.deployment.serve.durable_log import read_log

    writes = pd.read_csv(folder / "writes.csv").set_index("k")["written"]
    latencies, missed, records = [], 0, 0
    for i in range(n):
        log = read_log(folder / "log", f"V{i:03d}")
        k = log["time"].values.astype("datetime64[s]").astype(np.int64) - int(start)
        inside = (k >= 0) & (k < seconds - 1)
        records += int(inside.sum())
        missed += int((log["status"].values[inside] == "BLIND").sum())
        missed += (seconds - 1) - int(inside.sum())
        ok = inside & np.isin(k, writes.index)
        lat = log["published"].values[ok] - writes.loc[k[ok]].values
        latencies.append(lat)
    lat = np.concatenate(latencies) * 1000.0
    cpu0, cpu1, t0, t1 = cpu
    used = (cpu1.user + cpu1.system) - (cpu0.user + cpu0.system)
    percent = 100.0 * used / (t1 - t0)
    rss = max(s[2] for s in samples) / 2**20
    print(f"valves {n}, plant seconds {seconds} (real time), records {records}")
    print(
        f"latency ms: median {np.median(lat):.1f}, p95 {np.percentile(lat, 95):.1f}, "
        f"p99 {np.percentile(lat, 99):.1f}, max {lat.max():.1f}"
    )
    print(f"missed seconds (BLIND or absent, all valves): {missed}")
    print(f"serve CPU: {percent:.1f} % of one core in all, {percent / n:.3f} % per valve")
    print(
        f"serve memory (peak RSS): {rss:.0f} MiB in all, {rss / n:.2f} MiB per valve "
        "(including the interpreter and libraries)"
    )


if __name__ == "__main__":
    sys.exit(main())
