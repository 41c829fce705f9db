"""SGDS-PF parameters: Table 2 presets by snr, overrides and validation."""
import pytest

from tbd_taichi.errors import ParameterError
from tbd_taichi.methods.sgds.params import PAPER_SALIENCY, SGDSParams, snr_band


@pytest.mark.parametrize("snr,band,l_ib,n_sump,t_pe,t_ptp,t_ft,t_rt", [
    (3.0, 0, 256, 4000, 0.1, 5, 0.7, 9), (2.0, 0, 256, 4000, 0.1, 5, 0.7, 9), (1.9, 1, 200, 6000, 0.1, 5, 0.5, 9),
    (1.6, 2, 150, 6000, 0.1, 5, 0.5, 8), (1.4, 3, 150, 8000, 0.2, 4, 0.2, 6), (1.2, 4, 100, 8000, 0.2, 4, 0.11, 5)])
def test_table2_presets_lie_in_the_papers_ranges(snr, band, l_ib, n_sump, t_pe, t_ptp, t_ft, t_rt):
    p = SGDSParams.for_snr(snr)
    assert snr_band(snr) == band
    assert (p.L_ib, p.N_sump, p.T_PE, p.T_PTp, p.T_ft, p.T_rt) == (l_ib, n_sump, t_pe, t_ptp, t_ft, t_rt)
    assert p.N_tpf == 500 and p.snr == snr


def test_default_is_the_papers_unknown_snr_choice():
    assert SGDSParams.for_snr() == SGDSParams.for_snr(1.4)
    assert SGDSParams.for_snr().T_devr == pytest.approx(2 / 1.3)


def test_overrides_and_their_validation():
    assert SGDSParams.for_snr(2.0, P_e=0.15, L_ib=64).L_ib == 64
    with pytest.raises(ParameterError, match="unknown SGDS-PF parameter.*Pe"):
        SGDSParams.for_snr(2.0, Pe=0.1)
    with pytest.raises(ParameterError, match=r"P_e = 1.5 must be in \[0, 1\)"):
        SGDSParams.for_snr(2.0, P_e=1.5)
    with pytest.raises(ParameterError, match="T_ft"):
        SGDSParams.for_snr(2.0, T_ft=0.0)
    with pytest.raises(ParameterError, match=r"icef_window = 2.5 must be an integer in \[1, 1000\]"):
        SGDSParams.for_snr(2.0, icef_window=2.5)
    with pytest.raises(ParameterError, match="icef_window = 0"):
        SGDSParams.for_snr(2.0, icef_window=0)
    with pytest.raises(ParameterError, match="icef_mean_ratio"):
        SGDSParams.for_snr(2.0, icef_mean_ratio=0.0)
    with pytest.raises(ParameterError, match="icef_area_exponent = -0.5 must be ≥ 0"):
        SGDSParams.for_snr(2.0, icef_area_exponent=-0.5)
    with pytest.raises(ParameterError, match=r"confirm_window = -1 must be an integer in \[0, 1000\]"):
        SGDSParams.for_snr(2.0, confirm_window=-1)
    with pytest.raises(ParameterError, match=r"confirm_mean_ratio = 0.0 must be in \(0, 1\]"):
        SGDSParams.for_snr(2.0, confirm_mean_ratio=0.0)
    with pytest.raises(ParameterError, match=r"lef_memory = 1.0 must be in \[0, 1\)"):
        SGDSParams.for_snr(2.0, lef_memory=1.0)
    with pytest.raises(ParameterError, match="lef_scale = 0 must be > 0"):
        SGDSParams.for_snr(2.0, lef_scale=0)
    with pytest.raises(ParameterError, match="msw_reference = 'tracks' must be one of candidates, search"):
        SGDSParams.for_snr(2.0, msw_reference="tracks")
    paper = SGDSParams.for_snr(1.4, **PAPER_SALIENCY)
    assert paper.lef_memory == 0 and paper.msw_reference == "search"
    with pytest.raises(ParameterError, match="snr must be a number > 0"):
        SGDSParams.for_snr(-1)
