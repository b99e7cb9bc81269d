"""Security of the bus and of what services accept: identities and certificates (:mod:`.certs`),
the ``bus.security`` section (:mod:`.config`), access-control rules made from the rig
(:mod:`.acl`) and the one rule for names that become file names or keys (:mod:`.names`).

Below the transport (which turns the section into Zenoh's TLS, authentication and access-control
settings) and above the schema (the rules are made from its :class:`~flagtrack.daemon.schema.Keys`).
"""
