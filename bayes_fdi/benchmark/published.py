"""Published DAMADICS results, which the benchmark report sets beside its own.

:data:`PUBLISHED` lists each method, its source, the data it was scored on and its figures, as
the DAMADICS page of the documentation (``docs/damadics.md``) lists them with their citations;
`bayes_fdi.benchmark.report` prints them beside the benchmark's figures.
"""

from __future__ import annotations

__all__ = ["PUBLISHED"]

#: Published DAMADICS results (method, source, data, figures), as the DAMADICS page of the
#: documentation (``docs/damadics.md``) lists them with their citations.
PUBLISHED: tuple[tuple[str, str, str, str], ...] = (
    (
        "RVM residuals + k-means tree of RVCs",
        "Feng & Wang (the paper)",
        "DABLib sim + actual data; 10 states, whole runs",
        "accuracy: sim 99.60 % (SVM 98.53); actual 96.86 % (SVM 93.28)",
    ),
    (
        "Dynamic (LRGF) neural models, threshold 0.05",
        "Patan & Parisini, SAFEPROCESS 2003",
        "real Lublin data, f16 / f17 / f18",
        "F-model: t_dt 7 / 2 / 75 s; r_fd 0.092 / 0.263 / 0.326; r_td 0.953 / 0.998 / 0.93; "
        "t_it 0 / 1 / 76 s; r_fi 0.978 / 0.002 / 0.008; r_ti 1 / 0.998 / 0.93. X-model: t_dt "
        "13 / 3 / 46 s; r_fd 0.057 / 0.031 / 0.48; r_td 0.93 / 0.997 / 0.967; t_it 5 / 1 / 91 s; "
        "r_fi 0.432 / 0.296 / 0.007; r_ti 0.669 / 0.997 / 0.909",
    ),
    (
        "Dynamic GMDH NN residuals on F and X",
        "Mrugalski, Arinton & Korbicz 2003",
        "19 faults simulated (S/M/B + incipient) + real f17",
        "f5, f9, f12, f14 undetectable; every big fault detectable except f12, f14",
    ),
    (
        "Discrete HMM per condition",
        "de Almeida & Park",
        "DABLib sim, f16 f17 f18 + f17 inc.",
        "incipient f17 detected at strength 5.6 %, isolated at 27.8 %",
    ),
    (
        "Weighted constrained possibilistic C-means",
        "Bahrampour et al., Appl. Intell. 2011",
        "real Lublin segments",
        "detection after 20 samples; 10 false positives / 500 samples",
    ),
)
