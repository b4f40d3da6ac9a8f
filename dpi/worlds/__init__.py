"""Procedural worlds the priors train on: daylight skies, outdoor landscapes and streets, furnished rooms, drawn by one raycaster into HDR equirect maps."""
