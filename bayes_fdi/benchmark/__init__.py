"""The DAMADICS benchmark (an application): ``bayes-fdi benchmark``.

- `bayes_fdi.benchmark.scenarios`: the benchmark's 44 Step-I scenarios and fault-free hours.
- `bayes_fdi.benchmark.harness`: an online diagnoser scored on them with the PICalc indices
  (`bayes_fdi.scoring`), and the command; `bayes_fdi.benchmark.collection` scores each run and
  the calibration of the group probabilities.
- `bayes_fdi.benchmark.report`: ``benchmark.json`` and ``benchmark.md``.

An application: may import the library and the foundation, never `bayes_fdi.paper` or
`bayes_fdi.deployment`.
"""
