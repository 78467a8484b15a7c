"""Recordings from other systems (CSV, UFF 58, TDMS) read as devices, and the UFF export."""
