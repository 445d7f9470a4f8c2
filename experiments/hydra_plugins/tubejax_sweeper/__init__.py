"""Hydra plugins of the experiments apps (found by Hydra's plugin scan: ``experiments/`` is on
``sys.path`` when an app in it runs). See :mod:`hydra_plugins.tubejax_sweeper.planned_sweeper`."""
