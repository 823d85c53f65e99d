"""Hardware interfaces: projector, camera, serial trigger box, DLP LightCrafter over USB."""
