"""The .bws program language: parser, validation and generators."""

from bwsd.program.parser import SourceMap, parse_program, parse_program_with_positions
from bwsd.program.validate import load_program, validate

__all__ = [
    "SourceMap",
    "load_program",
    "parse_program",
    "parse_program_with_positions",
    "validate",
]
