import sys

from fuelhm_bench.cli import main

sys.exit(main())
