"""Stage 3, train: motion, energies, physiology, datasets, fitting, evaluation, export, runtime."""
