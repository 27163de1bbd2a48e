"""The hard-case suite (issue 7): inputs and fields built to break ddfbench, one file per case."""
