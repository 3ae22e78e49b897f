"""Multi-target tracking metrics: the GOSPA distance between true and estimated target sets."""
