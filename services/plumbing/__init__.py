"""What every gngdt process shares: its zenoh session (`session`) and how it starts and stops
(`lifecycle`)."""
