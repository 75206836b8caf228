import sys

from gen.synth.cli import main

sys.exit(main())
