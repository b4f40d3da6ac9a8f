# Diffusion prior rules (see issue 3).
