"""drillcosim: fmu_src package."""
