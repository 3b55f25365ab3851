"""Sources of motion: the default chewing task, tasks from CSV files, incisor tracking, and the smoothing that
estimates a task's rates. This package holds only the smoothing's window, so that the command line reads it
without loading NumPy."""

# Window length: 0.05 s passes the chewing band (cycles of ~0.8 s, harmonics below ~10 Hz) with an acceleration
# error of ~4e-4 of its peak and cuts noise above ~40 Hz (at 1 kHz sampling; measured in docs/tasks.md).
WINDOW_S = 0.05
