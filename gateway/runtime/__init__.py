"""The composition root: the daemon that builds the hub, the adapters and the front ends
(the only place that names them all), and its systemd notifications."""
