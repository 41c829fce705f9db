"""``ma-apf``: Bruno et al.'s auxiliary particle filter (§3.3) for a multiaspect target in GMRF clutter."""
from .multiaspect import method_spec

SPEC = method_spec("apf", "ma-apf", "multiaspect auxiliary PF", "auxiliary PF (first-stage weights from a prior "
                   "draw, a fresh draw, post-sampling selection)", rank=4)
