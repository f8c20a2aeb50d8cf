#!/usr/bin/env python3
"""Learn an FR5 policy from the scripted expert (DAgger). Logic lives in fr5_rl.training.imitation."""
import sys

from fr5_rl.training.imitation import main

if __name__ == "__main__":
    sys.exit(main())
