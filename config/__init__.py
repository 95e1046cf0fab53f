"""gngdt's example configuration files (the repository's config/): sensor profiles, zenoh
configurations, compose and two-host setups; `python -m gngdt.config` prints where they are."""
