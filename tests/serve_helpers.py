"""Helpers of the ``serve`` tests: a small fitted model, free ports, TOML files, certificates and
real subprocesses (``bayes-fdi simulate-plant`` and ``bayes-fdi serve``) on 127.0.0.1."""

from __future__ import annotations

import asyncio
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def fit_tiny_model(path: Path) -> Path:
    """A small online diagnoser (f1, f7, f18) fitted in seconds, saved to ``path``."""
    from bayes_fdi.actuator import Fault, benchmark_inputs, simulate
    from bayes_fdi.calibration import TemperatureScaler
    from bayes_fdi.diagnosis import OnlineDiagnoser
    from bayes_fdi.diagnosis.normal_models.dynamic import DynamicNormalModels

    normal = simulate(benchmark_inputs(4, 400, seed=1, vary=True), seed=1)
    specs = [Fault(f, s, 100.0) for f in ("f1", "f7", "f18") for s in (0.4, 0.6, 0.8, 1.0, 0.5)]
    faults = simulate(benchmark_inputs(len(specs), 300, seed=2, vary=True), specs, seed=2)
    models = DynamicNormalModels(
        x_widths=(8.0,),
        f_widths=(0.1,),
        evidence_max_samples=200,
        max_train_samples=300,
        calibration_folds=2,
        random_state=0,
    )
    diag = OnlineDiagnoser(models, calibrator=TemperatureScaler(), max_signatures_per_fault=20)
    diag.fit(normal, faults).save(path)
    return path


def free_ports(n: int) -> list[int]:
    """``n`` distinct free TCP ports on 127.0.0.1."""
    sockets = []
    for _ in range(n):
        s = socket.socket()
        s.bind(("127.0.0.1", 0))
        sockets.append(s)
    ports = [s.getsockname()[1] for s in sockets]
    for s in sockets:
        s.close()
    return ports


def make_certificate(folder: Path, name: str, uri: str) -> tuple[Path, Path]:
    """A self-signed certificate (DER) and key (PEM) made with asyncua's helper."""
    from asyncua.crypto.cert_gen import setup_self_signed_certificate
    from cryptography.x509.oid import ExtendedKeyUsageOID

    key, cert = folder / f"{name}-key.pem", folder / f"{name}-cert.der"
    use = [ExtendedKeyUsageOID.CLIENT_AUTH, ExtendedKeyUsageOID.SERVER_AUTH]
    asyncio.run(
        setup_self_signed_certificate(key, cert, uri, "localhost", use, {"commonName": name})
    )
    return cert, key


class Process:
    """A ``bayes-fdi`` subprocess whose output lines are collected by a thread."""

    def __init__(self, args: list[str], cwd: Path, env: dict[str, str] | None = None) -> None:
        full_env = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1", **(env or {}))
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "bayes_fdi", *args],
            cwd=cwd,
            env=full_env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            bufsize=1,
        )
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))

    def wait_for(self, text: str, timeout: float = 60.0) -> str:
        """The first output line containing ``text`` (AssertionError on timeout or exit)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            for line in list(self.lines):
                if text in line:
                    return line
            if self.proc.poll() is not None:
                self._reader.join(2)
                for line in self.lines:
                    if text in line:
                        return line
                break
            time.sleep(0.05)
        raise AssertionError(f"no line with {text!r}; output:\n" + "\n".join(self.lines[-40:]))

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 30.0) -> int:
        """Send ``sig`` (if still running) and wait; returns the exit status."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        try:
            rc = self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(10)
            self._reader.join(5)
            raise AssertionError(
                f"still running {timeout:.0f} s after signal {sig}; output:\n"
                + "\n".join(self.lines[-60:])
            ) from None
        self._reader.join(5)
        return rc

    @property
    def output(self) -> str:
        return "\n".join(self.lines)


def write_toml(
    path: Path,
    *,
    plant_port: int,
    seva_port: int,
    valves: dict[str, str],
    speed: float,
    extra_plant: str = "",
    server: str | None = None,
    simulation: str = "",
    log: str = "",
) -> Path:
    """A serve/simulate-plant TOML on 127.0.0.1 (``valves``: name -> its extra TOML lines)."""
    server = server or 'security = ["None"]\nallow_anonymous = true'
    text = f"""
[plant]
endpoint = "opc.tcp://127.0.0.1:{plant_port}/plant"
speed = {speed}
max_delay = {min(1.5, 2.0 / speed)}
clock_tolerance = {max(5.0, 4.0 * min(1.5, 2.0 / speed) * speed)}
reconnect_min = 0.1
reconnect_max = 0.2
publishing_interval = 0.05
{extra_plant}

[server]
endpoint = "opc.tcp://127.0.0.1:{seva_port}/seva"
{server}

[log]
folder = "log"
segment_seconds = 30
{log}

[simulation]
seed = 4
{simulation}
"""
    for name, lines in valves.items():
        text += f"\n[valves.{name}]\n{lines}\n"
    path.write_text(text)
    return path


def plant_second(time_values: np.ndarray, start: float) -> np.ndarray:
    """Seconds since the simulated plant's start of the log's date-times."""
    return time_values.astype("datetime64[s]").astype(np.int64) - int(start)
