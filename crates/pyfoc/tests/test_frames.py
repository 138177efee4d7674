"""pyfoc.to_frame: simulate's and the replay's results as polars DataFrames with named
vector fields."""
import numpy as np
import pytest

import pyfoc
from test_replay import SERVO


def test_simulate_and_replay_results_as_frames(tmp_path):
    path = tmp_path / "run.mcap"
    sim = pyfoc.simulate("default", duration=0.05, mcap=str(path))
    df = pyfoc.to_frame(sim)
    assert df.height == 500
    for c in ["t", "theta", "i_alpha", "i_beta", "i_d", "i_q", "u_alpha", "duty_a", "duty_c",
              "p_theta", "angle_error_deg", "controller_theta_est"]:
        assert c in df.columns, c
    assert "i_dq" not in df.columns and "metrics" not in df.columns
    np.testing.assert_array_equal(df["i_q"].to_numpy(), sim["i_dq"][:, 1])
    np.testing.assert_array_equal(df["duty_b"].to_numpy(), sim["duties"][:, 1])
    log = pyfoc.read_log(path)
    out = pyfoc.Ekf(pyfoc.Motor(**SERVO), 1e-4).run(log["u_ab"], log["i_ab"], u_prev=log["u_prev"])
    lf, of = pyfoc.to_frame(log), pyfoc.to_frame(out)
    assert lf.height == of.height == 500
    assert "u_prev" not in lf.columns and {"u_alpha", "i_beta", "theta_ref"} <= set(lf.columns)
    np.testing.assert_array_equal(of["theta"].to_numpy(), out["theta"])
    assert of["status"].dtype.is_integer()
    with pytest.raises(TypeError, match="result"):
        pyfoc.to_frame([1, 2])
