"""Metrics of the evaluation protocol: PV, SD, contact (here), and later CR, QR, DS, OPP, TS and tables."""
