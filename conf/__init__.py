"""The Hydra config tree of `parallax-train`, packaged as ``parallax.conf`` so an installed
parallax finds its YAML files; the settings themselves are in :mod:`parallax.config.schema`."""
