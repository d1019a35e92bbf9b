"""`python -m prlpid_fmi`: the prlpid-fmi command line."""
import sys

from prlpid_fmi.cli import main

sys.exit(main())
