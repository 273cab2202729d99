"""Where an RVR fit's peak memory is reached: resident set sampled during the fit, with the
Python stack of the fit at each new peak (companion of ``rvm_fit.py``).

Usage::

    OMP_NUM_THREADS=1 PYTHONPATH=$PWD python benchmarks/rvm_memory_profile.py --n 20000

Fits ``RVR`` as ``rvm_fit.py`` does (``make_data(n)`` of the problem, its RBF width, a bias
column, one thread) while a thread reads the process's resident set (``/proc/self/statm``)
every ``--interval`` seconds. Prints the resident set before the fit, the peak with the fit's
innermost package frames at the moment it was first reached, and the largest rises in between
with where they happened. Sampling misses peaks shorter than the interval; ``ru_maxrss`` at the
end is the kernel's exact peak. Linux only. Written by hand: a benchmark of this package's fit.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import threading
import time
import traceback
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from rvm_fit import PROBLEMS, make_data

__all__ = ["main"]

_PAGE_MB = os.sysconf("SC_PAGE_SIZE") / 2**20


def _rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * _PAGE_MB


def _where(frame_id: int, depth: int) -> str:
    """The innermost ``depth`` frames of the thread ``frame_id`` inside bayes_fdi or torch."""
    frame = sys._current_frames().get(frame_id)
    if frame is None:
        return "?"
    stack = [
        f"{Path(fs.filename).name}:{fs.lineno} {fs.name}"
        for fs in traceback.extract_stack(frame)
        if "bayes_fdi" in fs.filename
    ]
    return " < ".join(reversed(stack[-depth:])) or "outside bayes_fdi"


class RssSampler(threading.Thread):
    """Samples the resident set; keeps the peak and the rises of more than ``step`` MB with the
    fit's stack (``where``) when they were first seen."""

    def __init__(self, target_thread: int, interval: float, step: float, depth: int) -> None:
        super().__init__(daemon=True)
        self.target, self.interval, self.step, self.depth = target_thread, interval, step, depth
        self.stop = threading.Event()
        self.peak = _rss_mb()
        self.peak_where = "before the fit"
        self.events: list[tuple[float, float, str]] = []  # (seconds, MB, where)
        self.t0 = time.perf_counter()

    def run(self) -> None:
        last_event = self.peak
        while not self.stop.is_set():
            rss = _rss_mb()
            if rss > self.peak:
                self.peak = rss
                self.peak_where = _where(self.target, self.depth)
            if rss > last_event + self.step:
                self.events.append(
                    (time.perf_counter() - self.t0, rss, _where(self.target, self.depth))
                )
                last_event = rss
            elif rss < last_event - self.step:
                last_event = rss
            self.stop.wait(self.interval)


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problem", default="sinc", choices=sorted(PROBLEMS))
    ap.add_argument("--n", type=int, default=20000)
    ap.add_argument("--interval", type=float, default=0.01, help="sampling interval, s")
    ap.add_argument("--step", type=float, default=20.0, help="report rises above this, MB")
    ap.add_argument("--depth", type=int, default=4, help="package frames shown")
    args = ap.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    from bayes_fdi.rvm import RVR

    data = make_data(args.n, problem=args.problem)
    X, y = data["X_train"], data["y_train"]
    model = RVR(kernel="rbf", width=PROBLEMS[args.problem].sigma, bias=True)
    before = _rss_mb()
    sampler = RssSampler(threading.get_ident(), args.interval, args.step, args.depth)
    sampler.start()
    c0 = time.process_time()
    model.fit(X, y)
    cpu = time.process_time() - c0
    sampler.stop.set()
    sampler.join()
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(
        f"{args.problem} N={args.n}: fit {cpu:.1f} CPU s, {len(model.relevance_indices_)} RVs; "
        f"resident before the fit {before:.0f} MB, sampled peak {sampler.peak:.0f} MB at "
        f"{sampler.peak_where}; ru_maxrss {peak:.0f} MB"
    )
    for t, rss, where in sampler.events:
        print(f"  {t:8.1f} s  {rss:6.0f} MB  {where}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
