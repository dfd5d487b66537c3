"""The numpy reference: the method written readably, array by array.

The oracle of the tests (the native library gives the same bits) and the fallback where
no compiler built the native library.
"""
