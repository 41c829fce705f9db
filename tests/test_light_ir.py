"""Kernels marked ``kernels.loops.light_ir`` are compiled without Taichi's advanced IR passes, and only they: the
mark sits on the large frame-size kernels, the launch sees ``advanced_optimization=False`` while it compiles one
(and the runtime's setting again afterwards), and a marked kernel computes the same bits as an unmarked copy."""
import numpy as np
import pytest
import taichi as ti
from taichi.lang import impl

import tbd_taichi
from tbd_taichi import light_ir
from tbd_taichi.kernels import feature_fusion, multiaspect, phd, saliency
from tbd_taichi.kernels.loops import LIGHT_IR
from tbd_taichi.kernels.loops import light_ir as mark
from tbd_taichi.kernels.particles import step as particle_step
from tbd_taichi.kernels.populations import PopulationKernels

MARKED = [particle_step.StepMixin.step, particle_step.StepMixin.step_pair, saliency.frame_to_first_layer,
          saliency.accumulate_max, saliency.second_layer_and_lef, saliency.proposal_from_candidates,
          phd.PhdKernels.propagate, phd.PhdKernels.likelihood, phd.PhdKernels.update,
          feature_fusion.FeatureFusionKernels.step, multiaspect.MultiaspectKernels.propagate]


@pytest.fixture(autouse=True)
def cpu():
    tbd_taichi.init("cpu")


@mark
@ti.kernel
def marked(out: ti.types.ndarray(dtype=ti.f32, ndim=1), k: ti.f32):
    for i in range(out.shape[0]):
        x = ti.cast(i, ti.f32) * k
        out[i] = ti.exp(-x * x) + ti.sqrt(x * x + 1.0) / (x + 3.0)


@ti.kernel
def unmarked(out: ti.types.ndarray(dtype=ti.f32, ndim=1), k: ti.f32):
    for i in range(out.shape[0]):
        x = ti.cast(i, ti.f32) * k
        out[i] = ti.exp(-x * x) + ti.sqrt(x * x + 1.0) / (x + 3.0)


def test_the_frame_size_kernels_carry_the_mark_and_the_hand_over_does_not():
    assert light_ir.installed()
    for kernel in MARKED:
        assert getattr(kernel._primal, LIGHT_IR, False), kernel.__qualname__
    # measured slower without the advanced passes (1.2-1.3 against 1.5 ms a frame), and cheap to compile
    for kernel in (PopulationKernels.eliminate_and_hand_over, PopulationKernels.eliminate_and_hand_over_numbered):
        assert not getattr(kernel._primal, LIGHT_IR, False)


def test_a_marked_kernel_compiles_without_advanced_optimisation_and_restores_the_setting(monkeypatch):
    seen = []
    launch = light_ir._ORIGINAL["launch_kernel"]

    def recording(self, t_kernel, *args):
        seen.append((self.func.__name__, impl.current_cfg().advanced_optimization))
        return launch(self, t_kernel, *args)

    monkeypatch.setitem(light_ir._ORIGINAL, "launch_kernel", recording)
    out = np.zeros(5, np.float32)
    marked(out, 0.5)
    unmarked(out, 0.5)
    assert seen == [("marked", False), ("unmarked", True)]
    assert impl.current_cfg().advanced_optimization is True


@pytest.mark.parametrize("n", [1, 7, 1000])
def test_marked_and_unmarked_kernels_give_the_same_bits(n):
    a, b = np.zeros(n, np.float32), np.zeros(n, np.float32)
    marked(a, 0.37)
    unmarked(b, 0.37)
    assert np.array_equal(a.view(np.uint32), b.view(np.uint32))
    assert np.all(np.isfinite(a)) and a[0] == np.float32(1.0 + 1.0 / 3.0)
