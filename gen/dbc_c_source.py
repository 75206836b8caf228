"""`cantools generate_c_source`, through cantools' own subcommand but not its command line: that
imports every subcommand first, matplotlib with `plot` among them, most of the 2 s this step took
in each build folder. The same arguments, the same code, the same files."""

from __future__ import annotations

import argparse

from cantools.subparsers import generate_c_source


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m gen.dbc_c_source")
    generate_c_source.add_subparser(parser.add_subparsers(required=True))
    args = parser.parse_args(argv)
    args.func(args)


if __name__ == "__main__":
    main()
