"""Test fixtures (synthetic tables and signals for the tests and doctests); not product code.

Modules
-------
diagnosis
    Synthetic indicator tables for the healthy model, ITL and signature tests.
indicators
    Synthetic flight signals with known indicator values.
"""
