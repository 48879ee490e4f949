"""Support code of the test suite (not tests): FMU builders, fuzzers, logging helpers."""
