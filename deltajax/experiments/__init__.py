"""Experiments runnable with ``python -m deltajax.run experiment=<module name>``."""
