"""Relevance Vector Machines (sparse Bayesian learning) in torch."""
