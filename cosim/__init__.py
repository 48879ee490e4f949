"""drillcosim: cosim package."""
