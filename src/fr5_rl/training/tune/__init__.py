"""Hyperparameter and seed sweeps on Ray Tune: what ``rosrun fr5_rl tune.py`` runs.

Each trial is a :func:`fr5_rl.training.train.train` run (VecNormalize, checkpoints, the
evaluation callback) of a hyperparameter file with sampled values set. After every evaluation
the trial reports its success rate and step count to Tune and hands Tune a checkpoint (the run
directory's model, statistics, config and summary), so a trial whose worker or node dies is
retried from there, on any node. ASHA stops weak trials at its rungs.

The modules, in the order a sweep uses them (each imports only those before it):

- :mod:`.search_space`: the search file (``config/search_<algo>_<task>.yaml``,
  :class:`~.search_space.SearchFile`), its samplers as Tune domains, one trial's hyperparameters;
- :mod:`.settings`: the experiment's settings (:func:`~.settings.build_settings`), saved for ``--resume``;
- :mod:`.trial`: what a Ray worker runs for one trial (:func:`~.trial.run_trial`);
- :mod:`.results`: rows, table, plot, best hyperparameters and best model from Tune's results;
- :mod:`.experiment`: the driver (:class:`~.experiment.TuneExperiment`).

Ray itself is reached through :mod:`fr5_rl.training.ray_compat`, inside functions only: importing
these modules needs no Ray. The experiment writes into its output directory:

- ``results.csv`` / ``results.json``: one row per trial, best first (:func:`~.results.sort_rows`);
- ``success_vs_steps.png``: evaluation success against steps, one line per trial;
- ``best_hyperparams.yaml``: the best trial's hyperparameters, for ``train.py --hyperparams``;
- ``best_model/``: the best trial's model directory (``model.zip``, ``vecnormalize.pkl``,
  ``meta.json``, ``model.onnx``), for ``evaluate.py``, ``export_onnx.py`` and the policy node;
- ``tune/``: Ray Tune's experiment (trial checkpoints), which ``--resume`` continues;
- ``tune_settings.json``: everything ``--resume`` needs to rebuild the experiment.
"""
