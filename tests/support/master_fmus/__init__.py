"""Tiny pythonfmu FMUs used by the co-simulation master tests."""
