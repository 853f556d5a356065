"""Deployment: a loom's folder (`bwsd init`), the shipped examples (`bwsd examples`) and the
systemd units of an installation (`bwsd service install`), docs/service.md."""
