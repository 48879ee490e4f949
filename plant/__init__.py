"""drillcosim: plant package."""
