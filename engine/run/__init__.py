"""Planning and running jobs: automatic settings, pilot, batches, executors."""
