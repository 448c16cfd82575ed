import os
import sys

# Lets the test modules here (and worker processes, which get this sys.path) import `runner_testkit`.
sys.path.insert(0, os.path.dirname(__file__))
