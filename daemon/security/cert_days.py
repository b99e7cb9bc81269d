"""How long certificates last, apart from :mod:`.certs` so that ``flagtrack certs --help`` can show
the defaults without importing ``cryptography``."""

CA_DAYS = 3650
"""Validity of a new CA: 10 years (its key stays off the rig; rotating it means new certificates everywhere)."""
LEAF_DAYS = 730
"""Validity of an identity's certificate: 2 years (``flagtrack certs check`` says when to renew)."""
WARN_DAYS = 30
"""``flagtrack certs check`` fails for a certificate that expires within this many days."""
