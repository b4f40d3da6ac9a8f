"""A scene's decompositions as assets other tools open: one glTF binary and one USD stage with every sample as a
variant (material and light), the env maps beside them as .hdr and .exr."""
