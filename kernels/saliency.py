"""Multi-frame saliency extraction (SGDS-PF Eqs. 20–33) as Taichi kernels: every name of the stage, one
module to import.  The code lives by concept in

* :mod:`.saliency_lanes`: the 8-lane row layout and its helpers,
* :mod:`.saliency_maxfilter`: the streamed max filters, I_se and the first layer (Eqs. 20–22),
* :mod:`.saliency_lef`: the second layer, T_acc2 and the intensity range, the LEF and the multi-frame LEF
  (Eqs. 22–28),
* :mod:`.saliency_proposal`: the candidate pixels and the per-block proposal map (Eqs. 24, 29–33),
* :mod:`.saliency_fields`: :class:`SaliencyFields`, the engine's fields as the kernels' one template argument.

The pipeline kernels take the engine's fields as one ``SaliencyFields`` argument ``f`` (constants r, n_chunks,
serial fixed with it; snr, N, A, γ and lef_scale in its ``params64``/``params32`` fields), plus the per-frame
slots and scales; the NumPy twin is of this module as a whole.

Layout: an image (H, W) is a field of 8-lane vectors (H, ⌈W/8⌉) along x (SIMD rows); ring buffers add a
leading slot axis; padding lanes past W read as "outside the image".  The fields have the extents of the frame's
size class (``loops.frame_class``), and the kernels read the frame's own (``f.dims``) at run time, so one compiled
set serves every frame size of a class.

Every kernel runs in IEEE f32 (the runtime starts with fast_math off) and adds in a fixed order, so the
NumPy twin ``tbd_taichi.numpy_kernels.saliency`` reproduces the same bits except after exp().  Loops run
row by row: the outer loop over rows is parallel, or serial when the template argument ``serial`` is True
(small images, where a parallel launch costs more than the work).

Border rule (both engines): out-of-image pixels are ignored by the max filters and contribute 0 to the
sums (the energy sum of Eq. 21 and the 5×5 correlation of Eq. 27).
"""
from .saliency_lanes import *  # noqa: F401,F403
from .saliency_lanes import LANES, LEF_NO_CAP, NEG_INF, ROW_BLOCK, VEC, VEC64  # noqa: F401
from .saliency_maxfilter import *  # noqa: F401,F403
from .saliency_lef import *  # noqa: F401,F403
from .saliency_proposal import *  # noqa: F401,F403
from .saliency_fields import SaliencyFields  # noqa: F401
