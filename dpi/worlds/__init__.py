"""Procedural worlds the priors train on: daylight skies (Mitsuba's sun and sky model), outdoor landscapes and streets, furnished rooms, drawn by one raycaster into HDR equirect maps."""
