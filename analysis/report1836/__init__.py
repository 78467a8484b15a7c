"""DTMB Report 1836's chain: motions from gage signals (Eq 1-13), damping constants (Eq 14-17),
effective stock lengths (Appendix B), virtual mass and inertias (Eq 18-21), and Table 2 recomputed."""
