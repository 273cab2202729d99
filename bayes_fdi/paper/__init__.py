"""The paper's reproduction (an application): ``bayes-fdi reproduce``.

Feng & Wang's experiment end to end: the two campaigns (`bayes_fdi.paper.datasets`), the
protocol's constants and node classifiers (`bayes_fdi.paper.setup`), the protocol on one dataset
(`bayes_fdi.paper.pipeline`), its scores (`bayes_fdi.paper.scores`,
`bayes_fdi.paper.separability`, `bayes_fdi.paper.calibration_headlines`), and the Markdown report
(`bayes_fdi.paper.report`, built from `report_tables`, `report_figures` and `report_sections`).
`bayes_fdi.paper.reproduce` is the command.

An application: may import the library and the foundation, never `bayes_fdi.benchmark` or
`bayes_fdi.deployment`.
"""
