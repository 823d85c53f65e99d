"""The operator console: a local web application (``rig console``) that runs the scanner from a browser."""
