"""Benchmarks: ``python -m skinrs.bench {bbw,lbs,reduce}``. Each prints a table; none is a test."""
