# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 04 - HIL comparison: which controller steers best where
#
# Every controller runs the same closed-loop passes on the bench: the simulated tractor
# behind the emulated steering bridge and GPS receivers, the vehicle loop at 20 Hz in
# lockstep, the same seeds (so the same soil, slope and GPS errors) for every controller.
# Here, to keep the notebook short, four controllers meet three conditions once:
#
# * `kinematic` - the paper's LQR on the kinematic model at the measured speed;
# * `pure-pursuit` and `stanley` - today's open-source autosteer laws, tuned by `hil tune`;
# * `oracle` - an LQG designed on each condition's truth linearisation: the practical limit.
#
# The controllers designed from identified models (`design lqr`, `design robust`) join the
# same campaign as controller files; the README's main command does that for all 15
# conditions. The bench is calibrated against the paper's Table 2 (notebook 06).

# %%
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from IPython.display import Image, display

from hil.bench.runs.campaign import Campaign
from hil.truth.conditions import condition_for
from hil.bench.runs.report import cells, table2_text, write_report

t0 = time.perf_counter()
OUT = Path("nb_out")
CONTROLLERS = ["kinematic", "pure-pursuit", "stanley", "oracle"]
CONDITIONS = [condition_for("none", 1.00), condition_for("disker", 1.79), condition_for("ripper", 2.24)]

# %% [markdown]
# ## The campaign
# Each pass is saved as it finishes (`nb_out/campaign/runs/*.json`): running this cell
# again only runs what is missing.

# %%
campaign = Campaign(OUT / "campaign", CONTROLLERS, CONDITIONS, seeds=[7], duration=30.0)
results = campaign.run("local", workers=2)
print(f"{len(results)} passes")

# %% [markdown]
# ## The paper's Table 2 layout
# Measured (GPS) cross-track over the engaged, settled cycles, in cm: bias and 1-sigma,
# the paper's bias/1-sigma for that gear and implement, and the ratio of 1-sigmas.

# %%
rows = cells(results)
for c in CONTROLLERS:
    print(table2_text(rows, c), "\n")

# %% [markdown]
# ## Ratio to the oracle
# How far each controller is from the practical limit (1-sigma / the oracle's).

# %%
fig, ax = plt.subplots(figsize=(7, 3.5))
labels = [f"{c.implement}\n{c.speed:.2f} m/s" for c in CONDITIONS]
width = 0.25
for i, ctrl in enumerate([c for c in CONTROLLERS if c != "oracle"]):
    ratios = [next(r["sigma_ratio_to_oracle"] for r in rows if r["controller"] == ctrl
                   and r["implement"] == c.implement and r["speed"] == c.speed) for c in CONDITIONS]
    ax.bar([k + i * width for k in range(len(CONDITIONS))], ratios, width, label=ctrl)
ax.axhline(1.0, color="k", lw=0.8)
ax.set_xticks([k + width for k in range(len(CONDITIONS))], labels)
ax.set_ylabel("1-sigma / oracle's")
ax.legend(fontsize=8)
fig.tight_layout()
fig.savefig(OUT / "ratio_to_oracle.png", dpi=100)
display(Image(filename=str(OUT / "ratio_to_oracle.png")))
disker = {r["controller"]: r for r in rows if r["implement"] == "disker"}
for ctrl, r in disker.items():
    print(f"disker 1.79 m/s, {ctrl:>12}: true bias {r['true_bias_m'] * 100:+.1f} cm, "
          f"true 1-sigma {r['true_sigma_m'] * 100:.1f} cm")
# One 30 s pass per cell, with GPS outages and re-engages in it, is too little to rank
# biases; the main job's 60 s passes over 15 conditions are. Here: every pass steered.
assert all(r["engaged_fraction"] > 0.5 for r in results), "every controller engaged and kept the line"

# %% [markdown]
# ## The report
# Markdown and HTML with the tables, Figure 10 (1-sigma versus speed) and Figure 12
# (overlaid passes), and the data as CSV and JSON.

# %%
report = write_report(results, OUT / "report", title="HIL comparison (notebook 04)")
print("\n".join(report["files"]))
for name in report["files"]:
    if name.endswith(".png"):
        display(Image(filename=name))
print(f"notebook ran in {time.perf_counter() - t0:.1f} s")
