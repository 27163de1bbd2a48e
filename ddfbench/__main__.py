"""`python -m ddfbench`: see ddfbench.cli."""

from ddfbench.cli import main

if __name__ == "__main__":
    main()
