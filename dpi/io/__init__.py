"""Files in and out: EXR, LDR images and masks, structured files, atomic writes, locks, logs; where every
artefact of a run lives (layout) and the strict settings classes a config's values become (settings)."""
