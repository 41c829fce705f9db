"""``ma-rs``: Bruno et al.'s resample-move particle filter (§3.2) for a multiaspect target in GMRF clutter."""
from .multiaspect import method_spec

SPEC = method_spec("rs", "ma-rs", "multiaspect resample-move PF", "resample-move PF (bootstrap, multinomial "
                   "resampling, one Metropolis–Hastings move)", rank=3)
