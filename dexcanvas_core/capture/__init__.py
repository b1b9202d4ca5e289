"""Captures from other sources turned into DexCanvas trajectories (``dexcanvas import``)."""
