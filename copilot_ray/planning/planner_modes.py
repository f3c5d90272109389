"""The readings of pi_p a setting chooses among: its noise, its angle handling, its mean.

Plain tuples, apart from the planner itself, so that the settings table (which every command line reads
to check its flags) names them without importing torch.
"""

# absolute: one std for every layer (goal units); relative: a fraction of the parent segment's length.
NOISE_MODES = ("absolute", "relative")
# How pi_p treats a goal space's angles (`SubgoalPlanner.from_settings(..., geometry=)`): raw: as plain
# coordinates (the reference code, which only had positions); wrapped: short-way midpoints, wrapped samples;
# scaled: wrapped, and each dim's std divided by its distance weight (the same exploration in distance units).
ANGLE_MODES = ("raw", "wrapped", "scaled")
# free: the parents' midpoint plus the MLP's output, samples clipped into the box (the reference code);
# squashed: that mean mapped into the box by a tanh, so an update cannot throw it outside, where every
# clipped sample would land on one border point and leave the update no advantage to learn from;
# leaky: the free mean inside the box, and outside it the border plus LEAK x the overshoot (a gradient back).
MEAN_MODES = ("free", "squashed", "leaky")
