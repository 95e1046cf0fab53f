"""Where the logger's streams go: rerun (a .rrd file, a viewer), an MCAP recording."""
