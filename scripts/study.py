"""The published studies, each one command: ``python scripts/study.py STUDY [--docs] [--render-only]``.

The studies and their command live in :mod:`dospcot.lab.studies`; ``--help`` lists them.
"""

from dospcot.lab.studies import main

if __name__ == "__main__":
    main()
