"""``pyfoc.to_frame``: a result of ``simulate``, ``Ekf.run``, ``DriveObserver.run``,
``FluxObserver.run`` or ``read_log`` as a polars DataFrame, a row per PWM period or log row."""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

# Names of the columns of (N, k) arrays: vectors get named fields, not [0], [1].
FIELDS = {
    "i_ab": ("i_alpha", "i_beta"),
    "i_ab_meas": ("i_alpha_meas", "i_beta_meas"),
    "u_ab": ("u_alpha", "u_beta"),
    "i_dq": ("i_d", "i_q"),
    "duties": ("duty_a", "duty_b", "duty_c"),
    "p_diag": ("p_i_alpha", "p_i_beta", "p_omega", "p_theta"),
}


def to_frame(result: Mapping[str, Any]) -> Any:
    """The per-row arrays of ``result`` as columns: 1-D arrays as they are, (N, k) arrays split
    into named columns (``i_ab`` -> ``i_alpha``, ``i_beta``; ``i_dq`` -> ``i_d``, ``i_q``;
    ``duties`` -> ``duty_a`` .. ``duty_c``; ``p_diag`` -> ``p_i_alpha``, ``p_i_beta``,
    ``p_omega``, ``p_theta``; others ``NAME_0``, ``NAME_1``, ...). What is not per row
    (``metrics``, ``completed``, ``scenario``, ``u_prev``) is left out."""
    import polars as pl

    if not isinstance(result, Mapping):
        raise TypeError(f"result: expected the dict of a pyfoc call, got {type(result).__name__}")
    arrays = {k: v for k, v in result.items() if isinstance(v, np.ndarray) and v.ndim in (1, 2)}
    if "t" in arrays:
        n = len(arrays["t"])
    elif arrays:
        n = max(len(v) for v in arrays.values())
    else:
        return pl.DataFrame()
    columns: list[Any] = []
    for name, v in arrays.items():
        if len(v) != n:
            continue
        if v.ndim == 1:
            columns.append(pl.Series(name, v))
            continue
        names = FIELDS.get(name, ())
        if len(names) != v.shape[1]:
            names = tuple(f"{name}_{j}" for j in range(v.shape[1]))
        columns += [pl.Series(c, np.ascontiguousarray(v[:, j])) for j, c in enumerate(names)]
    return pl.DataFrame(columns)
