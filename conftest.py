"""Puts the repository root on sys.path so the tests can import the app (`app/`), which is not an
installed package (it is served with `panel serve app`)."""
