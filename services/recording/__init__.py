"""Recordings: read and write MCAP RGB-D recordings, render synthetic scenes, import real frames."""
