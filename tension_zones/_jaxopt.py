"""The one place jaxopt is imported.

jaxopt is no longer maintained and warns so on import; that warning is for us, not our users, so it
is silenced here (and only here). Every module imports ``jaxopt`` from this module.
"""

import warnings

with warnings.catch_warnings():
    warnings.filterwarnings("ignore", category=DeprecationWarning, module=r"jaxopt.*")
    warnings.filterwarnings("ignore", message=r".*JAXopt is no longer maintained.*")
    import jaxopt  # noqa: F401

__all__ = ["jaxopt"]
