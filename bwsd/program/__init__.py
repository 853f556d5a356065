"""The .bws program language: parser, validation and generators."""
