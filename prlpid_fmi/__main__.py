"""`python -m prlpid_fmi`: the prlpid-fmi command line."""
import sys

from .cli import main

sys.exit(main())
