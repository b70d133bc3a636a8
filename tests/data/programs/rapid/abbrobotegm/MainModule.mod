MODULE MainModule
    VAR egmident egmID1;
    
    PROC main()
        EGMReset egmID1;
        EGMGetId egmID1;
        EGMSetupUC ROB_1,egmId1,"EGMPathCorr","UCdevice"\PathCorr\APTR;
        EGMActMove EGMid1,MyTool.tframe\SampleRate:=48;
        MoveL StartPos,vmax,fine,MyTool\WObj:=WObj0;
        ! Move in X direction while Python applies Y corrections
        EGMMoveL egmID1,Offs(StartPos,400,0,0),v100,fine,MyTool\WObj:=WObj0;
        MoveL StartPos,vmax,fine,MyTool\WObj:=WObj0;
        EGMStop egmID1,EGM_STOP_HOLD;
    ENDPROC
ENDMODULE
