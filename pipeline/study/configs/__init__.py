"""Shipped study configs (TOML): the paper's default study, the design what-ifs and the
commented example. See :mod:`pipeline.study.config` and ``cryograting config --list``."""
