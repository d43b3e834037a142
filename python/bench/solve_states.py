"""Times ampc.Problem.solve on the states of a CSV (header x1..xn), as `trainer solve`
solves them: `python solve_states.py CONFIG STATES` (BENCHMARKS.md, "From Python")."""

import sys
import time

import numpy as np

import ampc

problem = ampc.Problem.from_file(sys.argv[1])
x = np.loadtxt(sys.argv[2], delimiter=",", skiprows=1, ndmin=2)
t = time.perf_counter()
u, du, status = problem.solve(x)
dt = time.perf_counter() - t
print(f"{len(x)} states in {dt:.3f} s ({1e3 * dt / len(x):.3f} ms per state), "
      f"{status.count('converged')} converged", file=sys.stderr)
