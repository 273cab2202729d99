"""Does the twin's stem error explain part of its flow residual? A measured alternative.

The twin simulates X' and F' from the recorded inputs; where its stem is off, its flow is off
through the valve law, ``dF'/dX' = -n (F' - o) / x_gain`` below the characteristic's knee. For
each recording (the real hour: fitted on its first half hour, scored on the second; a perturbed
plant of the commissioning benchmark: fitted on the first 80 % of its healthy hour, scored on
its held-out half hour), this script fits the twin as commissioning does (seed 0), takes the
residuals at its mode, and prints:

- the correlation of the X and F residuals on the held-out data, and the least-squares gain
  ``lam`` of the F residual on ``s_t e_X`` (``s_t`` the valve law's slope above), on the fitted
  and on the held-out data (1: the valve law alone explains it);
- the 95 % coverage of X and F on the held-out data of a model in which F's residual is
  ``lam s_t e_X + u`` (``lam`` from the fitted data, ``u`` the twin's AR(1) residual with its
  flow term fitted by `bayes_fdi.twin.model.noise_estimate` to what is left), 400 draws at the
  mode, beside the shipped twin's posterior predictive coverage.

Run: ``OMP_NUM_THREADS=1 PYTHONPATH=. python benchmarks/twin_flow_given_stem.py [--gain=G] real
0 1 2 3 4`` (about 40 CPU s per recording); ``--gain=1`` fixes ``lam`` at 1 (the valve law
alone) instead of fitting it.
"""

from __future__ import annotations

import sys

import numpy as np
import torch

from bayes_fdi.twin import ActuatorTwin
from bayes_fdi.twin.likelihood import ar1_from_innovations
from bayes_fdi.twin.model import flow_ratio, noise_estimate
from bayes_fdi.twin.simulator import WindowSimulator, cut_windows


def _data(which: str):
    if which == "real":
        from bayes_fdi.datasets import load_lublin_example

        hour = load_lublin_example()
        half = hour.sizes["time"] // 2
        return hour.isel(time=slice(0, half)), hour.isel(time=slice(half, None))
    from bayes_fdi.benchmark.plants import draw_plant, healthy_run
    from bayes_fdi.commissioning.commission import TWIN_FIT_SHARE

    plant = draw_plant(int(which))
    healthy = healthy_run(plant, 3600)
    fit = healthy.isel(time=slice(0, round(TWIN_FIT_SHARE * healthy.sizes["time"])))
    return fit, healthy_run(plant, 1800, heldout=True)


def _residuals(twin: ActuatorTwin, data):
    w = cut_windows(data, window=data.sizes["time"], settle=int(twin.settle), max_seconds=None)
    theta = np.array([getattr(twin.parameters_, n) for n in twin.names_])
    options = {"integrator": twin.integrator, "hold": twin.hold, "warmup": twin.warmup}
    sim = WindowSimulator(w.inputs, twin.base, twin.names_, **options)
    out = sim.outputs(theta[None])[0]
    p = np.stack([w.inputs[c].transpose("run", "time").values for c in ("P1", "P2")], -1)
    ratio = flow_ratio(torch.as_tensor(out[..., 1]), torch.as_tensor(theta), twin.names_,
                       twin.base, torch.as_tensor(p)).numpy()  # fmt: skip
    par = twin.parameters_
    slope = -par.characteristic * np.clip(out[..., 1] - par.f_offset, 0, None) / par.x_gain
    return w, w.observed - out, ratio, slope


def stem_gain(r, slope, mask):
    """Least-squares gain (through the origin) of the F residual ``r[..., 1]`` on the valve
    law's slope times the X residual, ``slope * r[..., 0]``, over the ``mask`` samples."""
    g = (slope * r[..., 0])[mask]
    return float(np.sum(g * r[..., 1][mask]) / np.sum(g * g))


def main(argv: list[str]) -> int:
    fixed = None
    if argv and argv[0].startswith("--gain="):
        fixed = float(argv[0].split("=", 1)[1])
        argv = argv[1:]
    rng = np.random.default_rng(0)
    for which in argv or ["real"]:
        fit, held = _data(which)
        twin = ActuatorTwin(random_state=0).fit(fit)
        w, r, ratio, slope = _residuals(twin, fit)
        lam = stem_gain(r, slope, w.mask) if fixed is None else fixed
        left = r.copy()
        left[..., 1] -= lam * slope * r[..., 0]
        z = noise_estimate(left, w.mask, ratio)
        sigma, phi, kappa = np.exp(z[:2]), np.tanh(z[2:4]), float(np.exp(z[4]))
        w, r, ratio, slope = _residuals(twin, held)
        m = w.mask
        n, runs = 400, m.shape[0]
        e_x = ar1_from_innovations(rng.standard_normal((n, *m.shape)), np.full((n, runs), sigma[0]),
                                   np.full((n, runs), phi[0]))  # fmt: skip
        scale = np.broadcast_to(np.sqrt(sigma[1] ** 2 + (kappa * ratio) ** 2), (n, *m.shape))
        u = ar1_from_innovations(rng.standard_normal((n, *m.shape)), scale,
                                 np.full((n, runs), phi[1]))  # fmt: skip
        cover = []
        for c, e in enumerate((e_x, lam * slope * e_x + u)):
            lo, hi = np.quantile(e, [0.025, 0.975], axis=0)
            cover.append(float(((r[..., c] >= lo) & (r[..., c] <= hi))[m].mean()))
        shipped = twin.check(held, seed=0).coverage
        corr = float(np.corrcoef(r[..., 0][m], r[..., 1][m])[0, 1])
        print(
            f"{which}: corr(e_X, e_F) {corr:+.2f}; gain fitted {lam:.2f}, held-out "
            f"{stem_gain(r, slope, m):.2f}; coverage X, F: F given X {cover[0]:.3f}, "
            f"{cover[1]:.3f}; "
            f"shipped {shipped['X']:.3f}, {shipped['F']:.3f}",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
