"""Plots written by the commands: one analysed impact, and a gap diagnosis."""
