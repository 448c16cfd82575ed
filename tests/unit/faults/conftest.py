import os
import sys

# Lets the test modules here share `faultkit` whatever pytest's import mode is.
sys.path.insert(0, os.path.dirname(__file__))
