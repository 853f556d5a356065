"""Exports of the predicted skeleton: JSON, TexGen .tg3, VTK .vtp."""
