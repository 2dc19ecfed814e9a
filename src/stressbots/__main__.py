"""``python -m stressbots``: the same as the ``stressbots`` command."""

from .cli import main

if __name__ == "__main__":
    main()
