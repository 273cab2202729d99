"""Deployment (an application): a diagnoser fitted for a valve and run on its recordings.

- `bayes_fdi.deployment.fitting`: ``bayes-fdi fit`` and the cached default model.
- `bayes_fdi.deployment.diagnose`: ``bayes-fdi diagnose``: recordings diagnosed second by
  second, in chunks, written by `bayes_fdi.deployment.stream_files`.

An application: may import the library and the foundation, never `bayes_fdi.paper` or
`bayes_fdi.benchmark` (a test checks that ``bayes-fdi diagnose`` loads none of their modules).
"""
