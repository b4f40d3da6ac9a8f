"""Light: environment maps, the sun, procedural skies, the tone curves of the prior's encoding."""
