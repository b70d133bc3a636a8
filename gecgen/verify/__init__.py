"""What a calibration achieves, stated: accuracy over a volume, ISO 9283 characteristics, checks and drift."""
