"""Byte-identical tracks: the CLI's tracks CSVs for fixed seeds, against files written before the code was
reshaped into the method registry (tests/data/golden, made by ``tests/data/golden/make.sh``).  A change that
alters one bit of a track on either engine fails here."""
from pathlib import Path

import numpy as np
import pytest

from tbd_taichi import cli

DATA = Path(__file__).parent / "data"
GOLDEN = DATA / "golden"
SCENES = {  # name: simulate arguments
    "sim50": ["--shape", "50", "50", "--frames", "70", "--snr", "2", "--seed", "3"],
    "sim100": ["--shape", "100", "120", "--frames", "60", "--snr", "1.6", "--targets", "2", "--seed", "5",
               "--motion", "transit"],
}
PAPER_HANDOVER = ["--param", "handover_frames=0", "--param", "backfill_frames=0"]
CASES = {  # golden file stem: (input, track arguments)
    "sgds_sim50": ("sim50", ["--method", "sgds", "--seed", "1"]),
    "pf_sim50": ("sim50", ["--method", "pf", "--seed", "1"]),
    "sgds_sim100_online": ("sim100", ["--method", "sgds", "--seed", "2", "--paths", "online"]),
    "pf_sim100": ("sim100", ["--method", "pf", "--seed", "2", "--snr", "1.6", "--particles", "20000"]),
    "sgds_drone021_real": ("drone021", ["--real-video"]),
    # Algorithm 2's uniform hand-over draw (handover_frames = 0) and no backfill: the files made before the
    # multi-frame hand-over (the real-video profile's snr 5 preset has both off, so its file is unchanged)
    "sgds_sim50_handover0": ("sim50", ["--method", "sgds", "--seed", "1", *PAPER_HANDOVER]),
    "sgds_sim100_online_handover0": ("sim100", ["--method", "sgds", "--seed", "2", "--paths", "online",
                                                *PAPER_HANDOVER]),
}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    root = tmp_path_factory.mktemp("golden")
    paths = {"drone021": DATA / "IR_DRONE_021.mp4"}
    for name, args in SCENES.items():
        paths[name] = root / f"{name}.npz"
        assert cli.main(["simulate", *args, "--out", str(paths[name])]) == 0
    return paths


@pytest.mark.parametrize("engine", ["taichi", "numpy"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_tracks_csv_is_byte_identical_to_the_golden_file(inputs, tmp_path, case, engine):
    source, args = CASES[case]
    out = tmp_path / "tracks.csv"
    assert cli.main(["track", str(inputs[source]), *args, "--engine", engine, "--out", str(out)]) == 0
    golden = GOLDEN / f"{case}_{engine}.csv"
    got, want = out.read_bytes(), golden.read_bytes()
    assert len(got.splitlines()) > 1, "the golden cases are chosen to give tracks"
    if got != want:
        diff = next(i for i, (a, b) in enumerate(zip(got.splitlines(), want.splitlines())) if a != b) \
            if len(got.splitlines()) == len(want.splitlines()) else "row count"
        pytest.fail(f"{case} on {engine}: tracks differ from {golden.name} (first differing line: {diff})")


def test_golden_scenes_are_the_simulator_s(inputs):
    """The goldens assume these inputs: a changed simulator must fail here, not in the tracks."""
    with np.load(inputs["sim50"]) as npz:
        assert npz["frames"].shape == (70, 50, 50)
        assert abs(float(npz["frames"].sum()) - float(np.load(GOLDEN / "sim50_checksum.npy"))) < 1e-3
