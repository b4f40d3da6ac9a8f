"""Rendering: the Mitsuba / Dr.Jit backend's set-up (backend) and the differentiable renderer of one textured
mesh under an environment map (renderer)."""
