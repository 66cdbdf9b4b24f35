"""`python -m paper`: run the paper's experiments and print paper vs ours."""

import sys


def main(argv=None) -> int:
    print("liepoisson paper reproductions: no experiments are available yet.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
