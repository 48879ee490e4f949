"""drillcosim: controller package."""
