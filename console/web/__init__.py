"""Every touch of viser's private internals, and the client guard, in one package."""
