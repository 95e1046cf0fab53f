"""gngdt services: capture, learner, logger, router and the `gngdt` command line."""
