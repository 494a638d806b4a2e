"""Batched JointState decoding (replay-rate path of the onboard node) against the per-message decoder."""
import numpy as np

from hd_bag.cdr import encode_jointstate, jointstate_layout
import hd_ros as ru


def test_decode_joint_states_matches_per_message_and_names_bad_ones():
    rng = np.random.default_rng(0)
    lay = jointstate_layout(["motor", "output"], "EMA-T1")
    n = 50
    st = 1_700_000_000_000_000_000 + np.arange(n, dtype=np.int64) * 1_000_000
    P, W, E = rng.standard_normal((3, n, 2))
    rows = encode_jointstate(lay, st, P, W, E)
    msgs = [r.tobytes() for r in rows]
    other = jointstate_layout(["motor", "output", "extra"], "EMA-T1")  # another layout, same stream
    msgs[10] = encode_jointstate(other, st[10:11], np.r_[P[10], 9.0][None], np.r_[W[10], 9.0][None],
                                 np.r_[E[10], 9.0][None])[0].tobytes()
    msgs[20] = msgs[20][:30]  # truncated
    bad = bytearray(msgs[30])
    bad[16] = 7  # frame_id corrupted: same length, other layout bytes -> per-message path
    msgs[30] = bytes(bad)
    stamps, V, frame, problems = ru.decode_joint_states(msgs)
    assert frame == "EMA-T1" and len(problems) == 1 and "JointState" in problems[0]
    keep = [i for i in range(n) if i != 20]
    np.testing.assert_array_equal(stamps, st[keep])
    for k, i in enumerate(keep):
        s, _, _, pos, vel, eff = ru.decode_joint_state(msgs[i])
        assert s == stamps[k]
        np.testing.assert_array_equal(V[k], np.r_[pos[:2], vel[:2], eff[:2]])
    np.testing.assert_array_equal(V[:, 4:6], E[keep])
