"""Recalibration and model discrepancy (work in progress)."""
