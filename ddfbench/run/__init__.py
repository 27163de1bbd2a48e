"""Running jobs: the runner (one shape x sampler x family x scene -> one record), record keys and storage,
launchers and their worker guard, sweep progress, and the MLflow mirror of the records.
"""
