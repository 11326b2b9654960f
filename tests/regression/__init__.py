"""Regression tests that pin an optimisation, not correctness.

Each keeps an earlier, simpler implementation as a reference and checks that the optimised code
still gives the same answer (bit for bit or to a stated tolerance). Correctness itself is
tested against independent ground truth in the package test folders.
"""
