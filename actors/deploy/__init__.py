"""A run across several hosts: the deploy plan (plan.py: hosts, endpoints, where each actor runs, security) and
what a host needs from the others (hosts.py: the setup a follower fetches, its config, the router, certificates)."""
