"""Numerical stability and many-run studies (issue 8).

- :mod:`.checks`: pre-run critical time steps from the case (Rayleigh, Hertz at the largest
  expected speed, contact damping, rolling and twisting springs, wall/servo speed against the
  neighbour skin) and the limits the in-deck monitors trip on;
- :mod:`.monitors`: reading the monitors' verdict from an engine log;
- :mod:`.executor` / :mod:`.sweep`: many runs through one executor (local processes or Dask);
- :mod:`.bisection`: the largest stable time-step fraction per case and engine;
- :mod:`.history`: probes with the monitor figures printed at every check (overlap against the
  settled packing's kinetic energy over f: physics or numerical heating);
- :mod:`.convergence`: error against run time over a ladder of one knob;
- :mod:`.calibration`: μ calibration in plane shear (seed 000 §3.2).
"""
