"""The observation vector's layout, without a server: packed and numeric scans give the
same vectors, frozen robots included."""

from __future__ import annotations

import copy

import numpy as np

from lasertag_env.observation import BEAMS, LASER_RANGE, ObservationLayout


def test_millimetres_over_the_range_are_the_metres_over_it_for_every_u16():
    # The packed path divides millimetres by 8000 in float32; the numeric path casts the
    # JSON's metres (mm / 1000 in float64) to float32 and divides by 8 (exact). The same,
    # for every value a packed beam can hold.
    mm = np.arange(65536, dtype=np.uint16)
    packed = np.divide(mm, np.float32(1000 * LASER_RANGE), dtype=np.float32)
    numeric = (mm / 1000.0).astype(np.float32) / np.float32(LASER_RANGE)
    assert packed.tobytes() == numeric.tobytes()


def observations(rng, robots):
    out = []
    for i in range(robots):
        frozen = i == 1  # a frozen robot's scan is empty
        mm = np.round(rng.uniform(0, 8.5, BEAMS) * 1000).astype("<u2")
        out.append({
            "scan": [] if frozen else (mm / 1000.0).tolist(),
            "hex": "" if frozen else mm.tobytes().hex(),
            "estimate": {"x": rng.uniform(-1, 25), "y": rng.uniform(-1, 17), "theta": 0.3},
            "spread": rng.uniform(0, 2), "tag_ready": True, "frozen": frozen,
            "detections": [{"range": rng.uniform(0, 8), "bearing": rng.uniform(-2, 2)}
                           for _ in range(int(rng.integers(0, 4)))],
            "teammates": [{"id": f"r{j}", "x": 1.0, "y": 2.0, "theta": -0.5, "age_ticks": 250,
                           "goal": [3.0, 4.0] if j == 0 else None}
                          for j in range(robots) if j != i],
            "belief": {"grid": rng.dirichlet(np.ones(16)).round(4).tolist(),
                       "paths": (0.5 * rng.dirichlet(np.ones(8))).round(4).tolist(),
                       "roles": rng.uniform(-1, 1, (2, 7)).round(4).tolist(),
                       "untagged": 0.5},
        })
    return out


def test_packed_and_numeric_scans_give_the_same_vectors():
    layout = ObservationLayout(robots=3, detections=2, width=24.0, height=16.0)
    rng = np.random.default_rng(7)
    for _ in range(20):
        raw = observations(rng, 3)
        numeric = [copy.deepcopy(o) for o in raw]
        packed = [dict(copy.deepcopy(o), scan=o["hex"]) for o in raw]
        one_by_one = np.stack(
            [layout.encode(copy.deepcopy(o), i, 0.25) for i, o in enumerate(numeric)]
        )
        together = layout.encode_all(numeric, 0.25)
        unpacked = layout.encode_all(packed, 0.25)
        assert one_by_one.tobytes() == together.tobytes() == unpacked.tobytes()
        # The raw observations get the scans as the JSON would have had them.
        assert [o["scan"] for o in packed] == [o["scan"] for o in raw]
        assert not together[1, :BEAMS].any()
        assert together.min() >= layout.low.min() and (together <= layout.high).all()
        # A team of one packed scan takes the same path as a whole team's.
        alone = layout.encode_all([copy.deepcopy(packed[0])], 0.25)
        assert alone[0, :BEAMS].tobytes() == together[0, :BEAMS].tobytes()
