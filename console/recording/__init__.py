"""Lab data out of the console: recordings (MCAP), the live Foxglove feed."""
