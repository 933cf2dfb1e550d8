import sys

from udc_render.cli import main

sys.exit(main())
