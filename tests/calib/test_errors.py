"""The calib error hierarchy."""

from __future__ import annotations

import pytest

from calib.errors import CalibrationError, DataError, ModelError


class TestHierarchy:
    """Every calib error is a CalibrationError and a ValueError."""

    @pytest.mark.parametrize("cls", [ModelError, DataError])
    def test_subclasses(self, cls: type[Exception]) -> None:
        """Each specific error derives from CalibrationError, itself a ValueError."""
        assert issubclass(cls, CalibrationError)
        assert issubclass(cls, ValueError)

    def test_catchable_as_value_error(self) -> None:
        """Callers that only know ValueError still catch calib errors."""
        with pytest.raises(ValueError, match="bad"):
            raise DataError("bad data")
