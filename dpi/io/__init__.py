"""Files in and out: EXR, LDR images and masks, Mitsuba XML, atomic writes, logs."""
