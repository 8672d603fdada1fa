"""The control page's HTTP routes: control, history, live stream and the quality view."""
