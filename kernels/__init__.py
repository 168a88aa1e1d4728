"""Warp device code for rodwarp, grouped by stage (elastics, broadphase, narrowphase, friction)."""
