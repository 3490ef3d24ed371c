"""The validation report's section on the structure: modes and a verdict."""

from __future__ import annotations

import warnings

import numpy as np


def structure_lines(estimator, X: list, y: list, dt: float) -> list[str]:
    """Markdown lines: the modes at rest and the non-linearity test on ``X, y``.

    The records are ones the fit did not see (``validate``'s), as the test
    needs. A model that keeps no linear model of its own gets the modes only,
    with the reason; an ensemble those of the network fitted to its median
    (``network_``), or, fitted without one, neither, with the reason.

    Examples
    --------
    A linear model with its poles at ``0.9 exp(+-0.3i)``:

    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> from sysid_nn import TDLRegressor
    >>> rng = np.random.default_rng(0)
    >>> u, a = rng.standard_normal((400, 1)), np.poly(0.9 * np.exp([0.3j, -0.3j]))
    >>> y = lfilter([0.0, 1.0], a.real, u[:, 0])
    >>> model = TDLRegressor(output_lags=2, input_lags=1, hidden_layer_sizes=(),
    ...                      n_init=1, random_state=0).fit(u, y)
    >>> print("\\n".join(structure_lines(model, [u], [y], 0.01)[2:5]))
    | mode | frequency [Hz] | 95 % interval | damping ratio | 95 % interval |
    |---|---|---|---|---|
    | 1 | 5.0605 | 5.0605-5.0605 | 0.3313 | 0.3313-0.3313 |
    """
    from sysid_nn._analysis._modal import modal_parameters
    from sysid_nn._analysis._nonlinearity import nonlinearity_test
    from sysid_nn._estimators._ensemble import one_network

    try:
        network = one_network(estimator)
    except ValueError as exc:
        return [f"No modes or non-linearity test: {exc}"]
    if network is not estimator:
        return [
            "Of the network fitted to the ensemble's median (`network_`):",
            "",
            *structure_lines(network, X, y, dt),
        ]
    modes = modal_parameters(estimator, dt)
    found = modes[modes.structural]
    lines = [
        f"Modes of the model's linearisation at rest (dt = {dt:g} s; "
        f"{len(modes) - len(found)} numerical mode(s) left out; see "
        "`sysid_nn.modal_parameters`):",
        "",
        "| mode | frequency [Hz] | 95 % interval | damping ratio | 95 % interval |",
        "|---|---|---|---|---|",
    ]
    for k, row in enumerate(found.itertuples(index=False), start=1):
        lines.append(
            f"| {k} | {row.frequency_hz:.4f} | {row.frequency_hz_low:.4f}-"
            f"{row.frequency_hz_high:.4f} | {row.damping_ratio:.4f} | "
            f"{row.damping_ratio_low:.4f}-{row.damping_ratio_high:.4f} |"
        )
    if not len(found):
        lines.append("| - | none | | | |")
    lines.append("")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # divergence is in the verdict
            result = nonlinearity_test(estimator, X, y)
    except ValueError as exc:
        lines.append(f"No non-linearity test: {exc}")
    else:
        lines.append(f"Non-linearity test on these records: {result.verdict}")
        if np.isfinite(result.statistic):
            lines.append(
                f"(HAC lag {result.lag} samples over {result.n_samples} samples.)"
            )
    return lines
