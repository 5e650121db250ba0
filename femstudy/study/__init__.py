"""The drilling study: case file → mesh → load histories → FE solutions → results folder."""
