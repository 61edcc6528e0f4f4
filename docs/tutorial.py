# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Tutorial: from a simulated session to the stability measured from data
#
# The paper's section 6 measures how stable a subject's bouncing is from the impacts alone:
# a VAR(1) fitted to the deviations of (v_k, theta_k) from their means estimates the map's
# Jacobian (eq. 9), whose spectral radius (eq. 10) says how fast a perturbation dies out.
# Here we do that on a lab session with known truth: simulate it at Fig. 8's parameters, extract
# the impacts from the sampled positions, fit, and compare with the model's eq. 10.
# Everything runs in memory through `bounce_cli`'s Python API; each step is the command of the
# same name.

# %%
import io
import tempfile
from pathlib import Path

from IPython.display import Image

import bounce_cli


def show(figure):
    """A figure of a result, as the PNG the command writes."""
    png = io.BytesIO()
    figure.savefig(png, format="png")
    return Image(png.getvalue())


FIG8 = {"model.alpha": 0.42, "model.g": 5.8, "model.racket_amplitude": 0.065,
        "model.racket_period": 0.55}
params = bounce_cli.ModelParams(alpha=0.42, g=5.8, racket_amplitude=0.065, racket_period=0.55)
fixed = params.fixed_point()                       # eqs. 7, 8
model = bounce_cli.stability(params)               # eqs. 9, 10
print(f"v~ = {fixed.v_m_s:.4f} m/s, theta~ = {fixed.theta_deg:.2f} deg, "
      f"spectral radius {model.spectral_radius:.3f} ({model.regime} regime)")

# %% [markdown]
# ## 1. A simulated session: bounce simulate-recording
#
# Three trials of 40 s of steady bouncing, no perturbations, with section 6's velocity noise
# q_v = 0.04 m/s after each impact, both positions sampled at 200 Hz with 0.5 mm noise.

# %%
session = bounce_cli.run("simulate-recording", set={
    **FIG8, "trials": 3, "duration_s": 40.0, "perturbations.every": 0,
    "velocity_noise_m_s": 0.04, "seed": 3})
recording = session.frames["recording.csv"]
truth = session.frames["truth.csv"]               # the impacts the simulation made
recording.head()

# %%
show(session.figures["recording.png"])

# %% [markdown]
# ## 2. The impacts, extracted from the positions: bounce extract

# %%
impacts = bounce_cli.extract(recording, g=5.8)
print(f"{len(impacts)} impacts extracted, {len(truth)} simulated")
impacts[["trial", "k", "t_s", "theta_deg", "v_m_s", "racket_acc_g"]].head()

# %% [markdown]
# ## 3. The stability measured from the data: bounce acf --data
#
# The analysis takes the model at the data's racket (the means of its cycles) and the
# config's alpha and g; the trust study (how well a data set of this size pins the radius
# down) is kept small here.

# %%
folder = Path(tempfile.mkdtemp())
impacts.to_csv(folder / "impacts.csv", index=False)
fit = bounce_cli.run("acf", data=folder / "impacts.csv", set={
    "model.alpha": 0.42, "model.g": 5.8, "data_analysis.trust_repetitions": 20,
    "data_analysis.trust_bounces": [200, 400]})
for line in fit.summary:
    print(line)

# %%
stability = fit.frames["stability_data.csv"]
radius = stability[stability["quantity"] == "spectral_radius"]
radius[["source", "estimate", "ci_low", "ci_high"]]

# %% [markdown]
# The session *is* the model, so the radius measured from the extracted impacts should cover
# the model's eq. 10 value within its interval:

# %%
measured = radius[radius["source"] == "ols+jackknife"].iloc[0]
print(f"model {model.spectral_radius:.3f}; data {measured.estimate:.3f} "
      f"[{measured.ci_low:.3f}, {measured.ci_high:.3f}]")
assert measured.ci_low <= model.spectral_radius <= measured.ci_high

# %%
show(fit.figures["stability_data.png"])
