"""The plot of one stored pass, as ``rsodb show --plot`` saves it."""

from __future__ import annotations

import numpy as np

from rsodb.plotting import file_pyplot

__all__ = ["save_pass_plot"]


def save_pass_plot(stored, path) -> None:
    """Save the magnitudes of a stored pass against time (with errors, saturated samples marked)."""
    plt = file_pyplot()

    t_s = stored.t_s
    mag = stored.best_mag
    good = stored.valid & np.isfinite(mag)
    fig, ax = plt.subplots(figsize=(10, 4), constrained_layout=True)
    ax.errorbar(
        t_s[good],
        mag[good],
        yerr=stored.mag_err[good],
        fmt=".",
        ms=2,
        lw=0.5,
        alpha=0.7,
        label=f"{stored.band} ({good.sum()} points)",
    )
    saturated = good & stored.saturated
    if saturated.any():
        ax.plot(t_s[saturated], mag[saturated], "rx", ms=4, label="saturated")
    ax.invert_yaxis()
    ax.set_xlabel(f"seconds since {np.datetime_as_string(stored.start_utc, unit='ms')}Z")
    ax.set_ylabel(f"{stored.band} magnitude" + (" (1000 km)" if "1000 km" in stored.mag_convention else ""))
    ax.set_title(f"{stored.norad} {stored.name} - {stored.site.name} - {stored.pass_id}")
    ax.legend(loc="best")
    fig.savefig(path, dpi=120)
    plt.close(fig)
