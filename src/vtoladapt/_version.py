"""The package's version, here so that any module can name it in what it writes without importing the
package's entry points (``vtoladapt/__init__.py`` re-exports it)."""
__version__ = "0.1.0"
