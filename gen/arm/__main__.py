import sys

from gen.arm.cli import main

sys.exit(main())
