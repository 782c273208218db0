"""Identify the source paper's throttle from a CSV record and plot measured against simulated.

    python python/examples/identify_throttle.py [THROTTLE.csv]

Without an argument it first writes the paper's experiment (30 runs of 1000 samples at 3 ms,
3 % noise) to throttle.csv. Runs 0-24 train, 25-29 are the test runs. With matplotlib
installed it saves throttle.png (measured and simulated output of the first test run).
"""

import sys

import pandas as pd

import ctsid

path = sys.argv[1] if len(sys.argv) > 1 else "throttle.csv"
if len(sys.argv) == 1:
    ctsid.throttle_dataset(path, runs=30, samples=1000, tau=0.003, noise=0.03, seed=1)
data = pd.read_csv(path)

model = ctsid.identify(data, outputs=["y"], inputs=["u"], tau=0.003, run_column="run",
                       train="0-24", test="25-29", degree=3)
model.print()
for row in model.score(data[data.run >= 25], run_column="run"):
    print(f"test run {row['run']}: fit {row['fit_percent']:.1f} %")
model.save("throttle.json")

try:
    import matplotlib.pyplot as plt
except ImportError:
    sys.exit(0)
run = data[data.run == 25]
simulated = model.simulate(run)
plt.plot(run.t, run.y, color="0.6", label="measured")
plt.plot(run.t, simulated[:, 0], color="C3", label="simulated (free run)")
plt.xlabel("t (s)")
plt.ylabel("y (rad)")
plt.legend()
plt.savefig("throttle.png", dpi=120)
print("wrote throttle.png")
