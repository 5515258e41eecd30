"""Placeholder entry point; the node is built in issue 5."""

import sys


def main(args=None):
    print("profile_node: not implemented yet", file=sys.stderr)
    return 0
