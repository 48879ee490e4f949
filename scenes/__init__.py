"""The shipped scene files (TOML), installed as package data of ``drillcosim.scenes``."""
