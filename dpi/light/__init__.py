"""Light: environment maps, the sun, the tone curves of the prior's encoding."""
